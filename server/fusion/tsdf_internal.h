// Internal to server/fusion: per-frame state shared by tsdf.cc (integration)
// and marching_cubes.cc (meshing). Not part of the public interface.
#pragma once

#include <array>
#include <utility>
#include <cstdint>
#include <memory>
#include <vector>

#include <Eigen/Core>

#include "common/mesh.h"
#include "server/fusion/tsdf.h"
#include "server/fusion/voxel_blocks.h"
#include "common/worker_pool.h"

namespace holo {

// One pod as seen by the integrator: projection of world points into its
// depth and colour images, and its masked depth for this frame.
struct TsdfVolume::PodView {
  // Depth camera: p_cam = R · p_world + t.
  Eigen::Matrix3f R;
  Eigen::Vector3f t;
  Eigen::Vector3f center;  // camera centre, world
  float fx = 0, fy = 0, cx = 0, cy = 0;
  int width = 0, height = 0;
  bool distorted = false;
  std::array<double, 5> distortion{};
  // Colour camera: p_color = Rc · p_cam + tc (from the depth camera frame).
  bool registered = true;  // colour pixel = depth pixel
  Eigen::Matrix3f Rc;
  Eigen::Vector3f tc;
  float cfx = 0, cfy = 0, ccx = 0, ccy = 0;
  int cwidth = 0, cheight = 0;
  bool color_distorted = false;
  std::array<double, 5> color_distortion{};
  const uint8_t* color = nullptr;  // RGB8, cwidth × cheight
  // The colour as one 32-bit word per pixel (R | G << 8 | B << 16), for the
  // AVX2 gather; only for registered pods on that path with colour (else null).
  const uint32_t* color_words = nullptr;
  bool avx2 = false;        // undistorted and registered on an AVX2 CPU: the AVX2 path
  bool with_color = true;   // accumulate colour (TsdfOptions::integrate_color)
  // Masked depth (mm, 0 = unused) and the maximum of each 8×8 pixel tile.
  const uint16_t* depth = nullptr;
  const uint16_t* tile_max = nullptr;
  const uint16_t* tile_min = nullptr;  // 0 = the tile has an unusable pixel
  // Nonzero where a pixel sits on a depth edge (null = no edge filtering).
  const uint8_t* edge = nullptr;
  int tiles_x = 0, tiles_y = 0;
};

// Side of the pixel tiles whose depth range culls blocks and sub-blocks.
inline constexpr int kTileSide = 4;
// Tsdf at or above this is free space beyond the truncation band in every
// view (skip_truncated_cubes).
inline constexpr float kTsdfBandLimit = 0.999f;
inline constexpr int kEdgesPerBlock = 3 * kBlockVoxels;

// Per voxel row (j + 8·k) of a block, bit i = voxel i of the row (meshing).
struct TsdfVolume::RowMasks {
  enum Kind { kOk = 0, kNeg = 1, kSeen = 2 };  // usable as a cube corner; tsdf < 0; weight > 0
  uint8_t bits[3][kBlockSide * kBlockSide];
};

struct TsdfVolume::Scratch {
  explicit Scratch(int threads) : pool(threads) {}
  WorkerPool pool;

  // Integration.
  std::vector<PodView> views;
  std::vector<std::vector<uint16_t>> masked_depth;
  std::vector<std::vector<uint16_t>> tile_max;
  std::vector<std::vector<uint16_t>> tile_min;
  std::vector<std::vector<uint8_t>> edge;
  std::vector<std::vector<uint32_t>> color_words;
  std::vector<std::vector<BlockCoord>> pod_blocks;  // candidate blocks per pod, locally de-duplicated
  std::vector<uint32_t> touched_stamp;              // per block: frame stamp of the last touch
  uint32_t stamp = 0;
  std::vector<int32_t> active;                      // blocks touched this frame
  std::vector<uint8_t> fresh;                       // per block: allocated this frame, voxels not yet written
  std::vector<std::pair<uint64_t, int32_t>> order;  // (Morton code, block) for sorting
  std::vector<size_t> thread_block_views, thread_skipped, thread_free, thread_subs;

  // DownsampleInto's per-block accumulators (type known only there).
  std::shared_ptr<void> downsample_sums;
  template <typename T>
  std::vector<T>& downsample_sums_storage() {
    if (!downsample_sums) downsample_sums = std::make_shared<std::vector<T>>();
    return *static_cast<std::vector<T>*>(downsample_sums.get());
  }

  // Meshing.
  struct MeshVertex {
    Eigen::Vector3f position;
    Eigen::Vector3f normal;
    std::array<uint8_t, 3> color;
  };
  struct BlockOutput {
    int thread = 0;
    uint32_t vertex_begin = 0, num_vertices = 0;   // in thread_vertices[thread]
    uint32_t tri_begin = 0, num_tris = 0;           // in thread_tris[thread]
    uint32_t vertex_base = 0, tri_base = 0;         // in the output mesh
  };
  std::vector<std::vector<MeshVertex>> thread_vertices;
  std::vector<std::vector<std::array<uint32_t, 3>>> thread_tris;  // packed (block, edge) references
  std::vector<BlockOutput> block_output;
  std::vector<uint16_t> edge_vertex;  // per block and owned edge: local vertex index
  std::vector<int32_t> mesh_blocks;   // blocks that may hold a surface
  std::vector<RowMasks> row_masks;    // per block
};

}  // namespace holo
