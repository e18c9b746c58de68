// The stream mesh: what a capture site publishes every frame.
//
// The full-resolution marching-cubes mesh of a fused S8-QVGA frame has about
// 140 k triangles (8 mm voxels); sending, decoding and rendering that at
// 30 fps is what made the live call slow. Fine appearance does not need it:
// the viewer projects the pods' colour images onto the surface, so the mesh
// only has to carry the shape. The stream mesh is made in two steps:
//
//  1. Marching cubes over the same fused volume box-filtered onto a grid
//     `step` times coarser (TsdfVolume::DownsampleInto): the depth noise
//     that folds the full mesh into many small triangles averages out, the
//     surface moves little (the mean of a linear field is its value at the
//     box centre), and extraction costs a fraction of the full mesh's.
//  2. Only if the result is still above the triangle budget: its shortest
//     edges collapsed to their midpoints (edge_collapse.h; marching cubes'
//     slivers), and if that is not enough, meshoptimizer's quadric
//     simplifier (topology-preserving edge collapses) down to it.
//     Simplifying the full mesh instead took ~100 ms per frame here
//     (docs/fusion.md, "The stream mesh"); the coarse grid leaves it little
//     to do, and the quadric simplifier's cost grows with its input, not
//     with what it removes (4.4–5.6 ms for the last 18 % at S8-QVGA).
//
// Small fragments are dropped after extraction, as for the full mesh.
// The full-resolution mesh stays available from the volume (export, PLY).
#pragma once

#include <cstddef>
#include <memory>

#include "common/mesh.h"
#include "common/status.h"
#include "server/fusion/tsdf.h"

namespace holo {

struct StreamMeshOptions {
  // Sampling step of the fused volume for marching cubes (1 = every voxel).
  int step = 2;
  // Triangle budget; above it the mesh is simplified to it. 0 = no budget.
  // 10 k, one person's (holoport-server takes the synthetic workload's,
  // Workload::stream_triangles, 10 k per person): at S8-QVGA (16 mm samples,
  // ~22 k triangles from marching cubes) the mesh stays within 1.3 mm (mean)
  // of the full-resolution one and as close to the truth as at 20 k, and the
  // rendering viewer of a live call on one 2-core machine, whose per-mesh
  // work grows with the triangles, shows 29 instead of 22 fps (docs/live.md,
  // "Twenty-fifth session").
  size_t max_triangles = 10000;
  // Connected fragments with fewer triangles are dropped. 0 = keep all.
  size_t min_component_triangles = 50;
  // Above the budget, edges shorter than this many (coarse) voxels are
  // collapsed first (edge_collapse.h); the quadric simplifier then only runs
  // if that was not enough. 0 = quadric simplification only.
  float collapse_max_edge_voxels = 0.35f;
  Status Check() const;
};

struct StreamMeshStats {
  size_t coarse_triangles = 0;  // after extraction and fragment removal
  size_t triangles = 0;         // published
  double downsample_ms = 0, extract_ms = 0, simplify_ms = 0;  // wall (simplify: collapse + quadric)
  size_t collapses = 0;         // short edges collapsed
  bool quadric = false;         // meshoptimizer had to run
  float simplify_error = 0;     // meshoptimizer's relative error (0 when not simplified)
};

class StreamMesher {
 public:
  // `fine` gives voxel size, truncation and the other fusion options the
  // coarse volume inherits.
  static StatusOr<std::unique_ptr<StreamMesher>> Create(const TsdfOptions& fine, StreamMeshOptions options);
  ~StreamMesher();

  // The stream mesh of `volume` (fused with the TsdfOptions given to Create)
  // into `out` (buffers reused): positions, MC normals, voxel colours if the
  // volume has them. Not thread-safe. `field` (optional) receives the grid
  // the mesh is extracted from (before fragment removal and simplification),
  // in world coordinates: what the G3 geometry codec sends
  // (protocol/surface_codec.h).
  Status Make(const TsdfVolume& volume, Mesh* out, StreamMeshStats* stats = nullptr, SdfGrid* field = nullptr);

  const StreamMeshOptions& options() const { return options_; }

 private:
  StreamMesher() = default;
  StreamMeshOptions options_;
  std::unique_ptr<TsdfVolume> coarse_;
  float coarse_voxel_m_ = 0;
  Mesh scratch_;
  std::vector<unsigned int> indices_, simplified_;
};

}  // namespace holo
