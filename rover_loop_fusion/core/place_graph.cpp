// The places that loops tie together (core/place_graph.h).
#include "rover_loop_fusion/core/place_graph.h"

#include <functional>
#include <queue>

namespace rover_loop_fusion {
namespace core {

void PlaceGraph::clear() {
  parent_.clear();
  size_.clear();
  adjacent_.clear();
}

size_t PlaceGraph::placeOf(size_t end) const {
  auto it = parent_.find(end);
  if (it == parent_.end()) {
    parent_.emplace(end, end);
    return end;
  }
  size_t root = it->second;
  while (true) {
    const size_t up = parent_.at(root);
    if (up == root) break;
    root = up;
  }
  for (size_t p = end; p != root;) {  // path compression
    size_t& up = parent_.at(p);
    p = up;
    up = root;
  }
  return root;
}

size_t PlaceGraph::endsOf(size_t place) const {
  const auto it = size_.find(place);
  return it == size_.end() ? 1 : it->second;
}

void PlaceGraph::keepShorter(std::unordered_map<size_t, double>& to, size_t place, double length) {
  const auto it = to.find(place);
  if (it == to.end())
    to.emplace(place, length);
  else if (length < it->second)
    it->second = length;
}

void PlaceGraph::addStretch(size_t a, size_t b, double length) {
  const size_t pa = placeOf(a), pb = placeOf(b);
  adjacent_[pa];
  adjacent_[pb];
  if (pa == pb) return;  // a stretch within a place: never shorter than the place's 0
  keepShorter(adjacent_[pa], pb, length);
  keepShorter(adjacent_[pb], pa, length);
}

void PlaceGraph::join(size_t a, size_t b) {
  size_t keep = placeOf(a), gone = placeOf(b);
  adjacent_[keep];
  adjacent_[gone];
  if (keep == gone) return;
  if (endsOf(keep) < endsOf(gone)) std::swap(keep, gone);  // the smaller place joins the larger
  parent_[gone] = keep;
  size_[keep] = endsOf(keep) + endsOf(gone);
  size_.erase(gone);
  std::unordered_map<size_t, double> moved;
  moved.swap(adjacent_[gone]);
  adjacent_.erase(gone);
  std::unordered_map<size_t, double>& into = adjacent_[keep];
  into.erase(gone);
  for (const auto& nb : moved) {
    if (nb.first == keep) continue;
    std::unordered_map<size_t, double>& back = adjacent_[nb.first];
    back.erase(gone);
    keepShorter(back, keep, nb.second);
    keepShorter(into, nb.first, nb.second);
  }
}

double PlaceGraph::shortest(const std::vector<std::pair<size_t, double>>& sources,
                            const std::vector<std::pair<size_t, double>>& targets, double bound) const {
  std::unordered_map<size_t, double> to_go;  // target place -> the shortest distance still to go
  for (const auto& t : targets) {
    if (parent_.count(t.first) == 0) continue;
    keepShorter(to_go, placeOf(t.first), t.second);
  }
  if (to_go.empty()) return bound;
  std::unordered_map<size_t, double> dist;
  using Item = std::pair<double, size_t>;
  std::priority_queue<Item, std::vector<Item>, std::greater<Item>> queue;
  for (const auto& s : sources) {
    if (parent_.count(s.first) == 0) continue;
    const size_t p = placeOf(s.first);
    const auto it = dist.find(p);
    if (it != dist.end() && it->second <= s.second) continue;
    dist[p] = s.second;
    queue.emplace(s.second, p);
  }
  double best = bound;
  while (!queue.empty()) {
    const Item top = queue.top();
    queue.pop();
    if (top.first >= best) break;  // every walk from here is at least this long
    if (top.first > dist.at(top.second)) continue;
    const auto target = to_go.find(top.second);
    if (target != to_go.end() && top.first + target->second < best) best = top.first + target->second;
    const auto adj = adjacent_.find(top.second);
    if (adj == adjacent_.end()) continue;
    for (const auto& nb : adj->second) {
      const double d = top.first + nb.second;
      if (d >= best) continue;
      const auto it = dist.find(nb.first);
      if (it == dist.end() || d < it->second) {
        dist[nb.first] = d;
        queue.emplace(d, nb.first);
      }
    }
  }
  return best;
}

}  // namespace core
}  // namespace rover_loop_fusion
