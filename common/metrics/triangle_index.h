// Closest-point queries against a triangle mesh, accelerated by a bounding
// volume hierarchy (binned-SAH BVH, ≤ 4 triangles per leaf).
//
// Build is O(n log n); a query near the surface of a 100k-triangle mesh
// visits a few dozen nodes. The index copies the vertex positions it needs,
// so it does not borrow the mesh. Queries are const and thread-safe, and the
// answer for a point does not depend on the thread count (ties between
// equally close triangles are broken by the fixed traversal order).
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

#include <Eigen/Core>

#include "common/mesh.h"
#include "common/status.h"

namespace holo::metrics {

struct ClosestPoint {
  static constexpr uint32_t kNoTriangle = std::numeric_limits<uint32_t>::max();
  // Index into Mesh::triangles, or kNoTriangle if nothing was within range.
  uint32_t triangle = kNoTriangle;
  // Euclidean distance from the query to `point`, metres (+inf if not found).
  float distance = std::numeric_limits<float>::infinity();
  // Closest point on the surface.
  Eigen::Vector3f point = Eigen::Vector3f::Zero();
  // Weights of the triangle's vertices 0, 1, 2 (non-negative, sum 1):
  // point = w0·v0 + w1·v1 + w2·v2.
  Eigen::Vector3f barycentric = Eigen::Vector3f::Zero();

  bool found() const { return triangle != kNoTriangle; }
};

// Queries per block when a batch of closest-point queries is split across
// threads: below this a thread hand-off costs more than it saves.
inline constexpr size_t kQueriesPerBlock = 256;

class TriangleIndex {
 public:
  // An empty index: every query returns "not found".
  TriangleIndex() = default;

  // Indexes every triangle of `mesh` (degenerate triangles included; they act
  // as segments or points). Fails with ValidateGeometry()'s DataLoss
  // if an index is out of range or a position is not finite. A mesh without
  // triangles gives an empty index.
  static StatusOr<TriangleIndex> Build(const Mesh& mesh);

  size_t num_triangles() const { return ids_.size(); }
  bool empty() const { return ids_.empty(); }

  // The closest surface point to `p` among points at distance ≤
  // `max_distance` (metres); not found if there is none. A finite
  // `max_distance` also makes the query faster.
  ClosestPoint Query(const Eigen::Vector3f& p,
                     float max_distance = std::numeric_limits<float>::infinity()) const;

  // Query() for every point, on `num_threads` threads (0 = all cores).
  // Result i belongs to points[i].
  std::vector<ClosestPoint> QueryBatch(const std::vector<Eigen::Vector3f>& points,
                                       float max_distance = std::numeric_limits<float>::infinity(),
                                       int num_threads = 0) const;

  // Distances only (metres; +inf where nothing is within `max_distance`).
  std::vector<float> DistanceBatch(const std::vector<Eigen::Vector3f>& points,
                                   float max_distance = std::numeric_limits<float>::infinity(),
                                   int num_threads = 0) const;

  // Reference answer by testing every triangle, for tests: O(n) per query.
  ClosestPoint QueryBruteForce(const Eigen::Vector3f& p) const;

 private:
  struct Node {
    Eigen::Vector3f lo, hi;  // bounding box of everything below
    uint32_t first = 0;      // leaf: first slot in tris_; inner: index of the left child (right = first + 1)
    uint32_t count = 0;      // leaf: number of triangles (> 0); inner: 0
  };
  struct Tri {
    Eigen::Vector3f a, b, c;
  };

  void TestLeaf(const Node& node, const Eigen::Vector3f& p, float& best_d2, ClosestPoint& best) const;

  std::vector<Node> nodes_;
  std::vector<Tri> tris_;      // triangles in leaf order
  std::vector<uint32_t> ids_;  // original triangle index of each slot in tris_
};

// Closest point to `p` on triangle (a, b, c), computed in double precision;
// handles degenerate triangles. Returns the point and writes the barycentric
// weights of a, b, c to `bary`.
Eigen::Vector3d ClosestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                       const Eigen::Vector3d& c, Eigen::Vector3d* bary);

}  // namespace holo::metrics
