#include "server/temporal/deformation_graph.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <unordered_map>

namespace holo {

using Eigen::Matrix3f;
using Eigen::Vector3f;

Status DeformationGraphOptions::Check() const {
  if (!(node_spacing_m > 0.002f && node_spacing_m < 1.0f))
    return InvalidArgument("node_spacing_m must be in (0.002, 1) m, got " + std::to_string(node_spacing_m));
  if (edges_per_node < 0 || edges_per_node > 32)
    return InvalidArgument("edges_per_node must be in [0, 32], got " + std::to_string(edges_per_node));
  if (!(max_edge_factor > 0 && max_edge_factor <= 10))
    return InvalidArgument("max_edge_factor must be in (0, 10], got " + std::to_string(max_edge_factor));
  if (!(max_skin_factor > 0 && max_skin_factor <= 4))
    return InvalidArgument("max_skin_factor must be in (0, 4], got " + std::to_string(max_skin_factor));
  return OkStatus();
}

Status DeformationGraph::Build(const std::vector<Vector3f>& surface, const DeformationGraphOptions& options) {
  HOLO_RETURN_IF_ERROR(options.Check());
  options_ = options;
  position_.clear();
  neighbors_.clear();
  const float s = options.node_spacing_m;
  // Voxel-grid sampling: per occupied cell, the point nearest to its centre.
  std::unordered_map<uint64_t, std::pair<float, int32_t>> cells;
  cells.reserve(surface.size() / 8 + 16);
  for (size_t i = 0; i < surface.size(); ++i) {
    const Vector3f& p = surface[i];
    if (!p.allFinite()) continue;
    const Eigen::Vector3f q = p / s;
    const int64_t cx = static_cast<int64_t>(std::floor(q.x())), cy = static_cast<int64_t>(std::floor(q.y())),
                  cz = static_cast<int64_t>(std::floor(q.z()));
    if (std::abs(cx) > (1 << 20) || std::abs(cy) > (1 << 20) || std::abs(cz) > (1 << 20)) continue;
    const uint64_t key = (static_cast<uint64_t>(cx + (1 << 20)) << 42) | (static_cast<uint64_t>(cy + (1 << 20)) << 21) |
                         static_cast<uint64_t>(cz + (1 << 20));
    const float d = (q - Vector3f(cx + 0.5f, cy + 0.5f, cz + 0.5f)).squaredNorm();
    auto [it, inserted] = cells.try_emplace(key, d, static_cast<int32_t>(i));
    if (!inserted && d < it->second.first) it->second = {d, static_cast<int32_t>(i)};
  }
  std::vector<std::pair<uint64_t, int32_t>> chosen;
  chosen.reserve(cells.size());
  for (const auto& [key, v] : cells) chosen.emplace_back(key, v.second);
  std::sort(chosen.begin(), chosen.end());  // deterministic node order
  for (const auto& c : chosen) position_.push_back(surface[static_cast<size_t>(c.second)]);
  const size_t n = position_.size();
  affine_.assign(n, Matrix3f::Identity());
  translation_.assign(n, Vector3f::Zero());
  global_.setIdentity();
  neighbors_.assign(n, {});
  cell_start_.clear();
  cell_nodes_.clear();
  grid_dim_ = {0, 0, 0};
  if (n == 0) return OkStatus();

  // Grid over the nodes.
  Vector3f lo = position_[0], hi = position_[0];
  for (const Vector3f& p : position_) {
    lo = lo.cwiseMin(p);
    hi = hi.cwiseMax(p);
  }
  grid_origin_ = lo;
  for (int a = 0; a < 3; ++a) grid_dim_[a] = static_cast<int>(std::floor((hi[a] - lo[a]) / s)) + 1;
  const int64_t num_cells = static_cast<int64_t>(grid_dim_[0]) * grid_dim_[1] * grid_dim_[2];
  if (num_cells > (int64_t{1} << 26)) return InvalidArgument("deformation graph: surface spans too many cells");
  cell_start_.assign(static_cast<size_t>(num_cells) + 1, 0);
  std::vector<int64_t> node_cell(n);
  for (size_t k = 0; k < n; ++k) {
    const Vector3f q = (position_[k] - lo) / s;
    const int x = std::min(grid_dim_[0] - 1, static_cast<int>(q.x()));
    const int y = std::min(grid_dim_[1] - 1, static_cast<int>(q.y()));
    const int z = std::min(grid_dim_[2] - 1, static_cast<int>(q.z()));
    node_cell[k] = CellIndex(x, y, z);
    ++cell_start_[static_cast<size_t>(node_cell[k]) + 1];
  }
  for (size_t c = 1; c < cell_start_.size(); ++c) cell_start_[c] += cell_start_[c - 1];
  cell_nodes_.resize(n);
  std::vector<int32_t> fill(cell_start_.begin(), cell_start_.end() - 1);
  for (size_t k = 0; k < n; ++k) cell_nodes_[static_cast<size_t>(fill[static_cast<size_t>(node_cell[k])]++)] =
      static_cast<int32_t>(k);

  // Edges: nearest nodes within max_edge_factor · spacing.
  const float max_d = options.max_edge_factor * s;
  const int r = static_cast<int>(std::ceil(options.max_edge_factor));
  std::vector<std::pair<float, int32_t>> cand;
  for (size_t k = 0; k < n; ++k) {
    cand.clear();
    const Vector3f q = (position_[k] - lo) / s;
    const int cx = static_cast<int>(q.x()), cy = static_cast<int>(q.y()), cz = static_cast<int>(q.z());
    for (int z = std::max(0, cz - r); z <= std::min(grid_dim_[2] - 1, cz + r); ++z)
      for (int y = std::max(0, cy - r); y <= std::min(grid_dim_[1] - 1, cy + r); ++y)
        for (int x = std::max(0, cx - r); x <= std::min(grid_dim_[0] - 1, cx + r); ++x) {
          const int64_t c = CellIndex(x, y, z);
          for (int32_t i = cell_start_[static_cast<size_t>(c)]; i < cell_start_[static_cast<size_t>(c) + 1]; ++i) {
            const int32_t m = cell_nodes_[static_cast<size_t>(i)];
            if (m == static_cast<int32_t>(k)) continue;
            const float d = (position_[static_cast<size_t>(m)] - position_[k]).norm();
            if (d <= max_d) cand.emplace_back(d, m);
          }
        }
    std::sort(cand.begin(), cand.end());
    const size_t keep = std::min(cand.size(), static_cast<size_t>(options.edges_per_node));
    for (size_t i = 0; i < keep; ++i) neighbors_[k].push_back(cand[i].second);
  }
  return OkStatus();
}

void DeformationGraph::SetIdentity() {
  std::fill(affine_.begin(), affine_.end(), Matrix3f::Identity());
  std::fill(translation_.begin(), translation_.end(), Vector3f::Zero());
  global_.setIdentity();
}

void DeformationGraph::FoldGlobalIntoNodes() {
  const Matrix3f r = global_.linear();
  const Vector3f t = global_.translation();
  for (size_t k = 0; k < position_.size(); ++k) {
    affine_[k] = r * affine_[k];
    translation_[k] = r * (position_[k] + translation_[k]) + t - position_[k];
  }
  global_.setIdentity();
}

SkinWeights DeformationGraph::Skin(const Vector3f& p) const {
  SkinWeights out;
  if (position_.empty() || !p.allFinite()) return out;
  const float s = options_.node_spacing_m;
  const float max_d = options_.max_skin_factor * s;
  const Vector3f q = (p - grid_origin_) / s;
  if (!(q.array() > -options_.max_skin_factor - 1).all() ||
      !(q.x() < grid_dim_[0] + options_.max_skin_factor + 1 && q.y() < grid_dim_[1] + options_.max_skin_factor + 1 &&
        q.z() < grid_dim_[2] + options_.max_skin_factor + 1))
    return out;
  const int cx = static_cast<int>(std::floor(q.x())), cy = static_cast<int>(std::floor(q.y())),
            cz = static_cast<int>(std::floor(q.z()));
  // K + 1 nearest (the last one sets d_max), grown ring by ring: ring r
  // covers every node within r · spacing.
  constexpr int kKeep = kSkinNodes + 1;
  float best_d[kKeep];
  int32_t best_n[kKeep];
  int found = 0;
  const int max_ring = static_cast<int>(std::ceil(options_.max_skin_factor));
  int done_ring = -1;
  for (int ring = 1; ring <= max_ring; ++ring) {
    for (int z = std::max(0, cz - ring); z <= std::min(grid_dim_[2] - 1, cz + ring); ++z)
      for (int y = std::max(0, cy - ring); y <= std::min(grid_dim_[1] - 1, cy + ring); ++y)
        for (int x = std::max(0, cx - ring); x <= std::min(grid_dim_[0] - 1, cx + ring); ++x) {
          // Skip cells of the rings already searched.
          if (done_ring >= 0 && std::abs(x - cx) <= done_ring && std::abs(y - cy) <= done_ring &&
              std::abs(z - cz) <= done_ring)
            continue;
          const int64_t c = CellIndex(x, y, z);
          for (int32_t i = cell_start_[static_cast<size_t>(c)]; i < cell_start_[static_cast<size_t>(c) + 1]; ++i) {
            const int32_t m = cell_nodes_[static_cast<size_t>(i)];
            const float d = (position_[static_cast<size_t>(m)] - p).norm();
            if (d > max_d) continue;
            // Insertion into the sorted best list.
            int j;
            if (found < kKeep) {
              j = found++;
            } else {
              if (d >= best_d[kKeep - 1]) continue;
              j = kKeep - 1;
            }
            while (j > 0 && best_d[j - 1] > d) {
              best_d[j] = best_d[j - 1];
              best_n[j] = best_n[j - 1];
              --j;
            }
            best_d[j] = d;
            best_n[j] = m;
          }
        }
    done_ring = ring;
    if (found == kKeep && best_d[kKeep - 1] <= ring * s) break;
  }
  if (found == 0) return out;
  const int k = std::min(found, kSkinNodes);
  const float d_max = found == kKeep ? best_d[kKeep - 1] : max_d;
  float sum = 0;
  for (int i = 0; i < k; ++i) {
    const float u = std::max(0.0f, 1.0f - best_d[i] / std::max(d_max, 1e-6f));
    out.node[static_cast<size_t>(i)] = best_n[i];
    out.weight[static_cast<size_t>(i)] = u * u;
    sum += u * u;
  }
  if (sum <= 1e-12f) {
    for (int i = 0; i < k; ++i) out.weight[static_cast<size_t>(i)] = 1.0f / static_cast<float>(k);
  } else {
    for (int i = 0; i < k; ++i) out.weight[static_cast<size_t>(i)] /= sum;
  }
  return out;
}

void DeformationGraph::BlendedTransform(const SkinWeights& s, Matrix3f* m, Vector3f* c) const {
  Matrix3f a = Matrix3f::Zero();
  Vector3f t = Vector3f::Zero();
  for (int i = 0; i < kSkinNodes; ++i) {
    const int32_t k = s.node[static_cast<size_t>(i)];
    if (k < 0) break;
    const float w = s.weight[static_cast<size_t>(i)];
    const size_t ku = static_cast<size_t>(k);
    a += w * affine_[ku];
    t += w * (position_[ku] + translation_[ku] - affine_[ku] * position_[ku]);
  }
  *m = global_.linear() * a;
  *c = global_.linear() * t + global_.translation();
}

Vector3f DeformationGraph::Warp(const Vector3f& p, const SkinWeights& s) const {
  Vector3f out = Vector3f::Zero();
  for (int i = 0; i < kSkinNodes; ++i) {
    const int32_t k = s.node[static_cast<size_t>(i)];
    if (k < 0) break;
    const size_t ku = static_cast<size_t>(k);
    out += s.weight[static_cast<size_t>(i)] * (affine_[ku] * (p - position_[ku]) + position_[ku] + translation_[ku]);
  }
  return global_ * out;
}

Vector3f DeformationGraph::WarpNormal(const Vector3f& n, const SkinWeights& s) const {
  Matrix3f a = Matrix3f::Zero();
  for (int i = 0; i < kSkinNodes; ++i) {
    const int32_t k = s.node[static_cast<size_t>(i)];
    if (k < 0) break;
    a += s.weight[static_cast<size_t>(i)] * affine_[static_cast<size_t>(k)];
  }
  // Normals transform with the inverse transpose (= A for a rotation).
  const Matrix3f m = global_.linear() * a;
  Vector3f out = m.determinant() > 1e-9f ? Vector3f(m.inverse().transpose() * n) : Vector3f(m * n);
  const float len = out.norm();
  return len > 1e-12f ? Vector3f(out / len) : n;
}

}  // namespace holo
