// Loop candidates that wait for their keyframes in rover_verifier_node, indexed twice: by what
// they wait for (a keyframe stamp, or a keyframe number) so that a new keyframe wakes only the
// candidates it may resolve, and by arrival so that the timeout looks at the oldest only.
// Every operation costs O(log n) plus what it returns, however many candidates wait (scanning
// all of them on every message made 20000 waiting candidates cost seconds per message).
// No ROS here: tested on its own (test/ros/test_waiting_candidates.cpp).
#pragma once

#include <algorithm>
#include <cstdint>
#include <limits>
#include <map>
#include <stdexcept>
#include <utility>
#include <vector>

namespace rover_loop_fusion {

template <typename T>
class WaitingCandidates {
 public:
  /// A keyframe a candidate waits for: by stamp (it can resolve once a keyframe with stamp >=
  /// key arrives; key = stamp - tolerance [ns]) or by number (once keyframe `key` arrives).
  struct Wait {
    bool by_stamp;
    int64_t key;
  };

  /// Adds a candidate received at `received` [s] that waits for `waits` (one or two); returns
  /// its id (ids grow with arrival).
  uint64_t add(T item, double received, const std::vector<Wait>& waits) {
    const uint64_t id = next_id_++;
    Entry& e = entries_[id];
    e.item = std::move(item);
    e.received = received;
    index(id, e, waits);
    return id;
  }

  /// Ids, in arrival order, of the candidates that wait for a keyframe with stamp key in
  /// [from_ns, ns] or number <= number. They stop waiting: rewait() them or take() them.
  std::vector<uint64_t> wake(int64_t ns, int64_t number,
                             int64_t from_ns = std::numeric_limits<int64_t>::min()) {
    std::vector<uint64_t> ids;
    collect(by_stamp_, ns, &ids, from_ns);
    collect(by_number_, number, &ids);
    std::sort(ids.begin(), ids.end());
    ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
    for (uint64_t id : ids) unindex(entries_.at(id));
    return ids;
  }

  /// A woken candidate waits again.
  void rewait(uint64_t id, const std::vector<Wait>& waits) {
    Entry& e = entries_.at(id);
    unindex(e);
    index(id, e, waits);
  }

  /// The oldest candidate, if it was received before `deadline` [s].
  bool oldestBefore(double deadline, uint64_t* id) const {
    if (entries_.empty() || !(entries_.begin()->second.received < deadline)) return false;
    *id = entries_.begin()->first;
    return true;
  }

  const T& get(uint64_t id) const { return entries_.at(id).item; }

  /// Removes a candidate and returns it.
  T take(uint64_t id) {
    auto it = entries_.find(id);
    if (it == entries_.end()) throw std::out_of_range("no waiting candidate with that id");
    unindex(it->second);
    T item = std::move(it->second.item);
    entries_.erase(it);
    return item;
  }

  /// All ids in arrival order.
  std::vector<uint64_t> ids() const {
    std::vector<uint64_t> out;
    for (const auto& e : entries_) out.push_back(e.first);
    return out;
  }

  size_t size() const { return entries_.size(); }
  bool empty() const { return entries_.empty(); }
  /// Index entries wake() has looked at so far: the work it did (for tests).
  size_t examined() const { return examined_; }

 private:
  typedef std::multimap<int64_t, uint64_t> Index;
  struct Entry {
    T item;
    double received = 0.0;
    std::vector<std::pair<Index*, Index::iterator>> waits;
  };

  void index(uint64_t id, Entry& e, const std::vector<Wait>& waits) {
    for (const Wait& w : waits) {
      Index* idx = w.by_stamp ? &by_stamp_ : &by_number_;
      e.waits.emplace_back(idx, idx->emplace(w.key, id));
    }
  }
  static void unindex(Entry& e) {
    for (auto& w : e.waits) w.first->erase(w.second);
    e.waits.clear();
  }
  void collect(const Index& idx, int64_t up_to, std::vector<uint64_t>* ids,
               int64_t from = std::numeric_limits<int64_t>::min()) {
    for (auto it = idx.lower_bound(from); it != idx.end() && it->first <= up_to; ++it) {
      ++examined_;
      ids->push_back(it->second);
    }
  }

  std::map<uint64_t, Entry> entries_;  // by arrival
  Index by_stamp_, by_number_;
  uint64_t next_id_ = 0;
  size_t examined_ = 0;
};

}  // namespace rover_loop_fusion
