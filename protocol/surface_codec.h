// G3 — the surface coded as what marching cubes reads (PROTOCOL.md §7.2,
// geometry codec id 4).
//
// The site's stream mesh is marching cubes over a coarse grid (16 mm at
// S8-QVGA): every vertex lies on a grid edge whose two samples have opposite
// signs, and every triangle follows from the signs of its cube's corners. So
// instead of the mesh (G1: ~14 bits per vertex for positions plus ~2.3 bits
// per triangle for connectivity) G3 sends what the mesh is made from:
//   * which samples are corners of a surface cube, and on which side of the
//     surface they lie (a ternary label per sample of the occupied 4³
//     bricks, coded with four causal neighbours' labels as context), and
//   * where the surface crosses each edge between samples of opposite
//     signs, on as many levels as the edge needs: about voxel/step levels
//     where the surface meets the edge squarely, fewer as it meets it at a
//     grazing angle (the surface's normal is estimated from the labels,
//     which both sides know before any crossing), down to none.
// The decoder runs marching cubes (common/marching_cubes_table.h) over the
// cubes whose eight corners are labelled and recomputes normals as G1 does:
// connectivity costs nothing, and a vertex costs its crossing's level.
// Every stream goes through G1's static rANS coder.
//
// Measured on the fused S8-QVGA stream (docs/codecs.md, "G3"): 6.5 KB per
// frame against G1's 19.7 KB at the same 2 mm step, with the same
// novel-view PSNR at the viewer. The crossings of a fused field are noisy
// at the scale of a few millimetres, so predicting one crossing from its
// neighbours (tried first: Lorenzo and planar predictors on the distance
// samples, then on the crossings) cost more bits than coding the level
// alone; spending levels by the edge's angle is what saved them.
//
// Why our own codec: the stream mesh is what we send most of, and no library
// in Debian codes a sparse distance field for marching cubes (Draco and G1
// code meshes). Sending the truncated distance field instead of the mesh is
// an idea from the literature on volumetric compression; the layout, the
// labels and the angle-dependent levels here are ours.
//
// Each blob decodes alone (every frame is a key frame).
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "common/mesh.h"
#include "common/sdf_grid.h"
#include "common/status.h"
#include "protocol/messages.h"

namespace holo::protocol {

class ByteReader;

// Largest grid G3 accepts: samples per axis, (nx + 4)·(ny + 4)·(nz + 4)
// (the decoder keeps one byte per sample with a margin of two), and
// occupied 4³ bricks (about 1.3 KB of decoder state each).
inline constexpr int kSurfaceMaxAxis = 4096;
inline constexpr uint64_t kSurfaceMaxSamples = uint64_t{1} << 24;
inline constexpr size_t kSurfaceMaxOccupiedBricks = 65536;
inline uint64_t SurfacePaddedSamples(int nx, int ny, int nz) {
  return (uint64_t(nx) + 4) * (uint64_t(ny) + 4) * (uint64_t(nz) + 4);
}

struct SurfaceEncodeOptions {
  // Quantization of a vertex's position along its grid edge, metres: the
  // edge is cut into L = round(voxel / step) levels (2..255) and a vertex is
  // decoded at the middle of its level, within voxel/(2L) of where marching
  // cubes on the input would put it. [voxel/255, voxel/2].
  float position_step_m = 0.002f;
  // Pieces of surface (cubes joined through a crossed edge they share) of
  // fewer triangles are left out, as the site's clean-up drops small mesh
  // fragments (StreamMeshOptions::min_component_triangles). 0 = keep all.
  size_t min_component_triangles = 50;
  Status Check() const;
};

struct SurfaceEncodeStats {
  size_t surface_cubes = 0;    // cubes with all corners observed and a sign change
  size_t dropped_cubes = 0;    // of those, in pieces below min_component_triangles
  size_t grid_samples = 0;     // of the input grid
  size_t occupied_bricks = 0;  // 4³ bricks with a labelled sample
  size_t labelled = 0;         // samples with a label
  size_t crossings = 0;        // edges with a coded crossing (≈ vertices)
  size_t brick_bytes = 0, label_bytes = 0, crossing_bytes = 0;
  size_t vertices = 0, triangles = 0;  // of the decoded mesh
};

// Encodes the surface of `grid` into a G3 blob appended to `out`.
// `decoded` (optional) receives the mesh a decoder makes from the blob.
// InvalidArgument if the grid is malformed (sizes, spacing, origin);
// OutOfRange if its surface does not fit the format's limits (a grid larger
// than kSurfaceMaxSamples is first cut to the box of the surface it keeps).
Status EncodeSurface(const SdfGrid& grid, const SurfaceEncodeOptions& options, std::vector<uint8_t>* out,
                     Mesh* decoded = nullptr, SurfaceEncodeStats* stats = nullptr);

namespace internal {
// The G3 body after the 12-byte geometry prefix (DecodeGeometry dispatches
// here): `nv` and `nt` are the prefix's counts, which the decoded mesh must
// match. DataLoss naming the field on malformed data.
Status DecodeSurfaceBody(ByteReader& r, uint32_t nv, uint32_t nt, Mesh* mesh);
}  // namespace internal

}  // namespace holo::protocol
