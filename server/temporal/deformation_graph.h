// Embedded deformation (ED) graph (Sumner, Schmid, Pauly 2007; as used by
// DynamicFusion / Fusion4D / Holoportation): nodes sampled uniformly on a
// model surface, each with an affine A_k and a translation t_k, plus a global
// rigid transform (R, T). A model point v is warped by its K = 4 nearest nodes
// with weights w_k (Sumner's (1 − d_k/d_max)², normalised):
//
//   v' = R · Σ_k w_k (A_k (v − g_k) + g_k + t_k) + T
//
// Nodes are connected to their nearest nodes (graph edges) for the
// regularisation term. The graph knows nothing about cameras; the tracker
// (nonrigid_tracker.h) solves for its parameters.
#pragma once

#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "common/status.h"

namespace holo {

inline constexpr int kSkinNodes = 4;

struct DeformationGraphOptions {
  // Node spacing on the surface, metres (a voxel grid of this size keeps the
  // point nearest to each occupied cell's centre). Holoportation: ~4–8 cm.
  float node_spacing_m = 0.07f;
  // Graph edges per node: its nearest nodes within max_edge_factor · spacing.
  int edges_per_node = 6;
  float max_edge_factor = 2.5f;
  // A point farther than this · spacing from every node is not skinned.
  float max_skin_factor = 2.5f;

  Status Check() const;
};

// The K nearest nodes of a point and their weights (sum 1). Unused entries
// have node −1 and weight 0.
struct SkinWeights {
  std::array<int32_t, kSkinNodes> node{-1, -1, -1, -1};
  std::array<float, kSkinNodes> weight{0, 0, 0, 0};
  bool valid() const { return node[0] >= 0; }
};

class DeformationGraph {
 public:
  // Samples nodes on `surface` (points on the model surface), connects them,
  // and sets every node to the identity. Keeps memory across calls.
  // InvalidArgument for bad options; an empty surface gives an empty graph.
  Status Build(const std::vector<Eigen::Vector3f>& surface, const DeformationGraphOptions& options);

  size_t num_nodes() const { return position_.size(); }
  const DeformationGraphOptions& options() const { return options_; }

  // Node k: rest position g_k, affine A_k, translation t_k.
  const Eigen::Vector3f& position(int k) const { return position_[static_cast<size_t>(k)]; }
  Eigen::Matrix3f& affine(int k) { return affine_[static_cast<size_t>(k)]; }
  const Eigen::Matrix3f& affine(int k) const { return affine_[static_cast<size_t>(k)]; }
  Eigen::Vector3f& translation(int k) { return translation_[static_cast<size_t>(k)]; }
  const Eigen::Vector3f& translation(int k) const { return translation_[static_cast<size_t>(k)]; }

  // Graph edges: the neighbours of node k (indices, nearest first).
  const std::vector<int32_t>& neighbors(int k) const { return neighbors_[static_cast<size_t>(k)]; }

  // Global rigid transform applied after the node warp.
  Eigen::Isometry3f& global() { return global_; }
  const Eigen::Isometry3f& global() const { return global_; }

  // Resets every node to the identity and the global transform too.
  void SetIdentity();
  // Folds the global transform into the nodes (A_k ← R A_k,
  // t_k ← R (g_k + t_k) + T − g_k) and resets it to the identity. The warp
  // of every point is unchanged.
  void FoldGlobalIntoNodes();

  // The K nearest nodes of `p` (rest pose) within max_skin_factor · spacing;
  // invalid (node[0] = −1) if there is none.
  SkinWeights Skin(const Eigen::Vector3f& p) const;

  // Warped position and normal (the normal is transformed by the blended
  // affine and renormalised; exact for rotations).
  Eigen::Vector3f Warp(const Eigen::Vector3f& p, const SkinWeights& s) const;
  Eigen::Vector3f WarpNormal(const Eigen::Vector3f& n, const SkinWeights& s) const;
  // The blended affine transform x ↦ M x + c of the skin (global included):
  // Warp(p, s) = M p + c for points with the same skin.
  void BlendedTransform(const SkinWeights& s, Eigen::Matrix3f* m, Eigen::Vector3f* c) const;

 private:
  // Dense grid over the nodes' bounding box (cell = spacing), CSR lists.
  int64_t CellIndex(int x, int y, int z) const {
    return (static_cast<int64_t>(z) * grid_dim_[1] + y) * grid_dim_[0] + x;
  }

  DeformationGraphOptions options_;
  std::vector<Eigen::Vector3f> position_;
  std::vector<Eigen::Matrix3f> affine_;
  std::vector<Eigen::Vector3f> translation_;
  std::vector<std::vector<int32_t>> neighbors_;
  Eigen::Isometry3f global_ = Eigen::Isometry3f::Identity();
  Eigen::Vector3f grid_origin_ = Eigen::Vector3f::Zero();
  std::array<int, 3> grid_dim_{0, 0, 0};
  std::vector<int32_t> cell_start_;  // grid cells + 1
  std::vector<int32_t> cell_nodes_;
};

}  // namespace holo
