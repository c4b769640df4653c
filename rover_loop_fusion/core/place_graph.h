// The places that loops tie together, for the path length (KeyframeGraph::pathLength: the
// metres of odometry between a match and a query, every loop a shortcut of length 0).
//
// A loop end is a keyframe that ends a loop. Loop ends joined by loops are one place (a
// union-find: a loop has length 0, so every end of a place is at distance 0 from every
// other). Two places are adjacent if a stretch of one segment's odometry runs from an end of
// one to an end of the other; the adjacency keeps the shortest such stretch. A path between
// two keyframes is then a walk over places, and its length the sum of its stretches: the same
// shortest path as over every loop end, but the search visits each place once, not each visit
// of it (a circuit driven many times is as many places as it has loop ends on one lap).
//
// Kept incrementally as loops come (join, addStretch); a removed loop may split a place,
// which a union-find cannot undo: the owner clears it and adds everything again.
#pragma once

#include <cstddef>
#include <unordered_map>
#include <utility>
#include <vector>

namespace rover_loop_fusion {
namespace core {

class PlaceGraph {
 public:
  /// Forget every place (before adding them all again).
  void clear();
  /// A stretch of odometry of `length` between the loop ends a and b: the places of a and b
  /// are adjacent, at most that far apart.
  void addStretch(size_t a, size_t b, double length);
  /// A loop between the loop ends a and b: their places become one.
  void join(size_t a, size_t b);
  /// The shortest walk from any source (a loop end, and the distance already covered to it)
  /// to any target (a loop end, and the distance still to go from it), or `bound` if none is
  /// shorter than `bound` (the search stops there).
  double shortest(const std::vector<std::pair<size_t, double>>& sources,
                  const std::vector<std::pair<size_t, double>>& targets, double bound) const;
  /// How many places there are (each a loop end or several tied by loops).
  size_t places() const { return adjacent_.size(); }

 private:
  size_t placeOf(size_t end) const;  // the union-find root; a new loop end is a place of its own
  size_t endsOf(size_t place) const;  // its loop ends (1 for a place not in size_)
  static void keepShorter(std::unordered_map<size_t, double>& to, size_t place, double length);

  mutable std::unordered_map<size_t, size_t> parent_;  // loop end -> parent (path compression)
  std::unordered_map<size_t, size_t> size_;             // place -> its loop ends, if more than one
  /// place -> adjacent place -> the shortest stretch between them (both directions).
  std::unordered_map<size_t, std::unordered_map<size_t, double>> adjacent_;
};

}  // namespace core
}  // namespace rover_loop_fusion
