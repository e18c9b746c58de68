#include "common/metrics/triangle_index.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>

#include <Eigen/Geometry>

#include "common/worker_pool.h"
#include "common/metrics/surface_sampling.h"

namespace holo::metrics {
namespace {

constexpr uint32_t kMaxLeafSize = 4;
constexpr int kSahBins = 16;
// Past this depth the build switches to median splits, which halve the
// range, so the tree depth stays below kMaxStack.
constexpr int kSahMaxDepth = 48;
constexpr int kMaxStack = 96;

struct Box {
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(std::numeric_limits<float>::infinity());
  Eigen::Vector3f hi = Eigen::Vector3f::Constant(-std::numeric_limits<float>::infinity());
  void Grow(const Eigen::Vector3f& p) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  void Grow(const Box& b) {
    lo = lo.cwiseMin(b.lo);
    hi = hi.cwiseMax(b.hi);
  }
  bool Valid() const { return (lo.array() <= hi.array()).all(); }
  // Half the surface area; only ratios matter for the SAH.
  float HalfArea() const {
    if (!Valid()) return 0;
    const Eigen::Vector3f e = hi - lo;
    return e.x() * e.y() + e.y() * e.z() + e.z() * e.x();
  }
};

// Squared distance from `p` to the box [lo, hi]; 0 inside.
inline float BoxDistance2(const Eigen::Vector3f& p, const Eigen::Vector3f& lo, const Eigen::Vector3f& hi) {
  const Eigen::Vector3f d = (lo - p).cwiseMax(p - hi).cwiseMax(0.0f);
  return d.squaredNorm();
}

Eigen::Vector3d ClosestOnSegment(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                 double* t_out) {
  const Eigen::Vector3d ab = b - a;
  const double len2 = ab.squaredNorm();
  const double t = len2 > 0 ? std::clamp((p - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
  *t_out = t;
  return a + t * ab;
}

// Indices of `points` sorted along a Morton (Z-order) curve over their
// bounding box, so that consecutive queries touch the same BVH nodes and
// triangles (better cache use). Only the processing order changes; each
// result still goes to its own index.
std::vector<uint32_t> SpatialOrder(const std::vector<Eigen::Vector3f>& points) {
  HOLO_CHECK(points.size() < std::numeric_limits<uint32_t>::max());
  Box box;
  for (const auto& p : points)
    if (p.allFinite()) box.Grow(p);
  const Eigen::Vector3f extent = (box.hi - box.lo).cwiseMax(1e-12f);
  auto spread = [](uint64_t v) {  // 21 bits → every third bit of 63
    v &= 0x1FFFFF;
    v = (v | v << 32) & 0x1F00000000FFFFull;
    v = (v | v << 16) & 0x1F0000FF0000FFull;
    v = (v | v << 8) & 0x100F00F00F00F00Full;
    v = (v | v << 4) & 0x10C30C30C30C30C3ull;
    v = (v | v << 2) & 0x1249249249249249ull;
    return v;
  };
  std::vector<std::pair<uint64_t, uint32_t>> keys(points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    uint64_t code = 0;
    if (points[i].allFinite() && box.Valid()) {
      constexpr float kMaxCell = 2097151.0f;  // 2^21 - 1
      const Eigen::Vector3f q =
          ((points[i] - box.lo).cwiseQuotient(extent) * kMaxCell).cwiseMax(0.0f).cwiseMin(kMaxCell);
      code = spread(static_cast<uint64_t>(q.x())) | spread(static_cast<uint64_t>(q.y())) << 1 |
             spread(static_cast<uint64_t>(q.z())) << 2;
    }
    keys[i] = {code, static_cast<uint32_t>(i)};
  }
  std::sort(keys.begin(), keys.end());
  std::vector<uint32_t> order(points.size());
  for (size_t i = 0; i < keys.size(); ++i) order[i] = keys[i].second;
  return order;
}

struct BuildContext {
  std::vector<Box> boxes;
  std::vector<Eigen::Vector3f> centroids;
  std::vector<uint32_t> order;  // triangle ids, permuted into leaf order
};

}  // namespace

Eigen::Vector3d ClosestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                                       const Eigen::Vector3d& c, Eigen::Vector3d* bary) {
  // Voronoi-region walk (vertex regions, then edge regions, then the face);
  // see Ericson, Real-Time Collision Detection, §5.1.5.
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) {
    *bary = {1, 0, 0};
    return a;
  }
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) {
    *bary = {0, 1, 0};
    return b;
  }
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) {
    *bary = {0, 0, 1};
    return c;
  }
  const double vc = d1 * d4 - d3 * d2;
  const double vb = d5 * d2 - d1 * d6;
  const double va = d3 * d6 - d5 * d4;
  const double sum = va + vb + vc;  // = |ab × ac|², zero for a degenerate triangle
  if (!(sum > 1e-12 * ab.squaredNorm() * ac.squaredNorm())) {
    // Degenerate (collinear or coincident vertices): the closest point is on
    // one of the three edges.
    double t0, t1, t2;
    const Eigen::Vector3d q0 = ClosestOnSegment(p, a, b, &t0);
    const Eigen::Vector3d q1 = ClosestOnSegment(p, b, c, &t1);
    const Eigen::Vector3d q2 = ClosestOnSegment(p, c, a, &t2);
    const double e0 = (p - q0).squaredNorm(), e1 = (p - q1).squaredNorm(), e2 = (p - q2).squaredNorm();
    if (e0 <= e1 && e0 <= e2) {
      *bary = {1 - t0, t0, 0};
      return q0;
    }
    if (e1 <= e2) {
      *bary = {0, 1 - t1, t1};
      return q1;
    }
    *bary = {t2, 0, 1 - t2};
    return q2;
  }
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const double v = d1 / (d1 - d3);
    *bary = {1 - v, v, 0};
    return a + v * ab;
  }
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const double w = d2 / (d2 - d6);
    *bary = {1 - w, 0, w};
    return a + w * ac;
  }
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    *bary = {0, 1 - w, w};
    return b + w * (c - b);
  }
  const double v = vb / sum, w = vc / sum;
  *bary = {1 - v - w, v, w};
  return a + v * ab + w * ac;
}

StatusOr<TriangleIndex> TriangleIndex::Build(const Mesh& mesh) {
  HOLO_RETURN_IF_ERROR(ValidateGeometry(mesh));
  TriangleIndex index;
  const size_t n = mesh.triangles.size();
  if (n == 0) return index;
  if (n >= std::numeric_limits<uint32_t>::max() / 2)
    return InvalidArgument("TriangleIndex: too many triangles (" + std::to_string(n) + ")");

  BuildContext ctx;
  ctx.boxes.resize(n);
  ctx.centroids.resize(n);
  ctx.order.resize(n);
  for (size_t t = 0; t < n; ++t) {
    Box box;
    for (uint32_t v : mesh.triangles[t]) box.Grow(mesh.positions[v]);
    ctx.boxes[t] = box;
    ctx.centroids[t] = 0.5f * (box.lo + box.hi);
    ctx.order[t] = static_cast<uint32_t>(t);
  }

  index.nodes_.reserve(2 * n / kMaxLeafSize + 2);
  index.nodes_.emplace_back();
  struct Task {
    uint32_t node, begin, end;
    int depth;
  };
  std::vector<Task> tasks = {{0, 0, static_cast<uint32_t>(n), 0}};
  while (!tasks.empty()) {
    const Task task = tasks.back();
    tasks.pop_back();
    Box bounds, centroid_bounds;
    for (uint32_t i = task.begin; i < task.end; ++i) {
      bounds.Grow(ctx.boxes[ctx.order[i]]);
      centroid_bounds.Grow(ctx.centroids[ctx.order[i]]);
    }
    index.nodes_[task.node].lo = bounds.lo;
    index.nodes_[task.node].hi = bounds.hi;
    const uint32_t count = task.end - task.begin;
    if (count <= kMaxLeafSize) {
      index.nodes_[task.node].first = task.begin;
      index.nodes_[task.node].count = count;
      continue;
    }

    int axis = 0;
    const Eigen::Vector3f extent = centroid_bounds.hi - centroid_bounds.lo;
    if (extent.y() > extent[axis]) axis = 1;
    if (extent.z() > extent[axis]) axis = 2;
    uint32_t mid = task.begin + count / 2;
    bool use_median = task.depth >= kSahMaxDepth || !(extent[axis] > 0);
    if (!use_median) {
      // Binned SAH on centroids along the widest axis.
      std::array<Box, kSahBins> bin_box;
      std::array<uint32_t, kSahBins> bin_count{};
      const float scale = kSahBins / extent[axis];
      auto bin_of = [&](uint32_t tri) {
        const int b = static_cast<int>((ctx.centroids[tri][axis] - centroid_bounds.lo[axis]) * scale);
        return std::clamp(b, 0, kSahBins - 1);
      };
      for (uint32_t i = task.begin; i < task.end; ++i) {
        const int b = bin_of(ctx.order[i]);
        bin_box[b].Grow(ctx.boxes[ctx.order[i]]);
        ++bin_count[b];
      }
      std::array<float, kSahBins> right_cost{};
      Box acc;
      uint32_t acc_count = 0;
      for (int b = kSahBins - 1; b > 0; --b) {
        acc.Grow(bin_box[b]);
        acc_count += bin_count[b];
        right_cost[b] = acc.HalfArea() * static_cast<float>(acc_count);
      }
      float best_cost = std::numeric_limits<float>::infinity();
      int best_split = -1;  // left = bins [0, best_split]
      acc = Box();
      acc_count = 0;
      for (int b = 0; b + 1 < kSahBins; ++b) {
        acc.Grow(bin_box[b]);
        acc_count += bin_count[b];
        if (acc_count == 0 || acc_count == count) continue;
        const float cost = acc.HalfArea() * static_cast<float>(acc_count) + right_cost[b + 1];
        if (cost < best_cost) {
          best_cost = cost;
          best_split = b;
        }
      }
      if (best_split < 0) {
        use_median = true;
      } else {
        const auto it = std::partition(ctx.order.begin() + task.begin, ctx.order.begin() + task.end,
                                       [&](uint32_t tri) { return bin_of(tri) <= best_split; });
        mid = static_cast<uint32_t>(it - ctx.order.begin());
      }
    }
    if (use_median) {
      mid = task.begin + count / 2;
      std::nth_element(ctx.order.begin() + task.begin, ctx.order.begin() + mid, ctx.order.begin() + task.end,
                       [&](uint32_t x, uint32_t y) {
                         const float cx = ctx.centroids[x][axis], cy = ctx.centroids[y][axis];
                         return cx < cy || (cx == cy && x < y);
                       });
    }
    const uint32_t left = static_cast<uint32_t>(index.nodes_.size());
    index.nodes_.emplace_back();
    index.nodes_.emplace_back();
    index.nodes_[task.node].first = left;
    index.nodes_[task.node].count = 0;
    tasks.push_back({left + 1, mid, task.end, task.depth + 1});
    tasks.push_back({left, task.begin, mid, task.depth + 1});
  }

  index.tris_.resize(n);
  index.ids_ = std::move(ctx.order);
  for (size_t i = 0; i < n; ++i) {
    const auto& t = mesh.triangles[index.ids_[i]];
    index.tris_[i] = {mesh.positions[t[0]], mesh.positions[t[1]], mesh.positions[t[2]]};
  }
  return index;
}

void TriangleIndex::TestLeaf(const Node& node, const Eigen::Vector3f& p, float& best_d2, ClosestPoint& best) const {
  const Eigen::Vector3d pd = p.cast<double>();
  for (uint32_t i = node.first; i < node.first + node.count; ++i) {
    const Tri& tri = tris_[i];
    Eigen::Vector3d bary;
    const Eigen::Vector3d q =
        ClosestPointOnTriangle(pd, tri.a.cast<double>(), tri.b.cast<double>(), tri.c.cast<double>(), &bary);
    const float d2 = static_cast<float>((q - pd).squaredNorm());
    if (d2 < best_d2 || (!best.found() && d2 <= best_d2)) {
      best_d2 = d2;
      best.triangle = ids_[i];
      best.point = q.cast<float>();
      best.barycentric = bary.cast<float>();
    }
  }
}

ClosestPoint TriangleIndex::Query(const Eigen::Vector3f& p, float max_distance) const {
  ClosestPoint best;
  if (nodes_.empty() || !(max_distance >= 0)) return best;
  float best_d2 = std::isinf(max_distance) ? max_distance : max_distance * max_distance;
  std::pair<uint32_t, float> stack[kMaxStack];
  int top = 0;
  stack[top++] = {0, BoxDistance2(p, nodes_[0].lo, nodes_[0].hi)};
  while (top > 0) {
    const auto [id, box_d2] = stack[--top];
    if (box_d2 > best_d2) continue;
    const Node& node = nodes_[id];
    if (node.count > 0) {
      TestLeaf(node, p, best_d2, best);
      continue;
    }
    const Node& l = nodes_[node.first];
    const Node& r = nodes_[node.first + 1];
    float dl = BoxDistance2(p, l.lo, l.hi), dr = BoxDistance2(p, r.lo, r.hi);
    uint32_t near = node.first, far = node.first + 1;
    if (dr < dl) {
      std::swap(near, far);
      std::swap(dl, dr);
    }
    // Push the far child first so the near one is visited next and shrinks
    // best_d2 before the far one is looked at.
    if (dr <= best_d2) stack[top++] = {far, dr};
    if (dl <= best_d2) stack[top++] = {near, dl};
  }
  if (best.found()) best.distance = std::sqrt(best_d2);
  return best;
}

std::vector<ClosestPoint> TriangleIndex::QueryBatch(const std::vector<Eigen::Vector3f>& points, float max_distance,
                                                    int num_threads) const {
  std::vector<ClosestPoint> out(points.size());
  const std::vector<uint32_t> order = SpatialOrder(points);
  ParallelForBlocks(points.size(), num_threads, kQueriesPerBlock, [&](size_t begin, size_t end) {
    for (size_t i = begin; i < end; ++i) out[order[i]] = Query(points[order[i]], max_distance);
  });
  return out;
}

std::vector<float> TriangleIndex::DistanceBatch(const std::vector<Eigen::Vector3f>& points, float max_distance,
                                                int num_threads) const {
  std::vector<float> out(points.size());
  const std::vector<uint32_t> order = SpatialOrder(points);
  ParallelForBlocks(points.size(), num_threads, kQueriesPerBlock, [&](size_t begin, size_t end) {
    for (size_t i = begin; i < end; ++i) out[order[i]] = Query(points[order[i]], max_distance).distance;
  });
  return out;
}

ClosestPoint TriangleIndex::QueryBruteForce(const Eigen::Vector3f& p) const {
  ClosestPoint best;
  float best_d2 = std::numeric_limits<float>::infinity();
  for (uint32_t i = 0; i < tris_.size(); ++i) {
    Node leaf;
    leaf.first = i;
    leaf.count = 1;
    TestLeaf(leaf, p, best_d2, best);
  }
  if (best.found()) best.distance = std::sqrt(best_d2);
  return best;
}

}  // namespace holo::metrics
