// Surface-to-surface accuracy of a reconstruction against a ground-truth mesh
// (Chamfer, Hausdorff, precision / completeness). Definitions: docs/metrics.md.
#pragma once

#include <cstddef>
#include <vector>

#include "common/mesh.h"
#include "common/metrics/surface_sampling.h"
#include "common/metrics/triangle_index.h"
#include "common/status.h"

namespace holo::metrics {

struct MeshDistanceOptions {
  // How many points to draw on each surface. `sampling.seed` is used for the
  // reconstruction and `sampling.seed + 1` for the truth.
  SamplingOptions sampling;
  // Also use every vertex of each mesh as a sample point (in addition to the
  // surface samples). Vertices referenced by no triangle are included too.
  bool include_vertices = false;
  // A sample counts as "matched" if its distance to the other surface is
  // ≤ this, metres (completeness and precision).
  double completeness_threshold_m = 0.01;
  // Percentile for the robust Hausdorff variant, in (0, 100].
  double hausdorff_percentile = 95.0;
  // Worker threads for the closest-point queries; 0 = all cores. Results do
  // not depend on it.
  int num_threads = 0;

  // OK, or InvalidArgument naming the bad field.
  Status Check() const;
};

// All distances in millimetres; fractions in [0, 1].
struct MeshDistanceResult {
  // Mean over reconstruction samples of the distance to the truth surface.
  double accuracy_mm = 0;
  // Mean over truth samples of the distance to the reconstruction surface.
  double completeness_distance_mm = 0;
  // (accuracy_mm + completeness_distance_mm) / 2.
  double chamfer_mm = 0;
  // max(largest recon→truth distance, largest truth→recon distance).
  double hausdorff_mm = 0;
  // max(P-th percentile recon→truth, P-th percentile truth→recon), P =
  // options.hausdorff_percentile (default 95), nearest-rank percentile.
  double hausdorff_percentile_mm = 0;
  // The two directional percentiles behind hausdorff_percentile_mm.
  double accuracy_percentile_mm = 0;
  double completeness_percentile_mm = 0;
  // Fraction of truth samples within the threshold of the reconstruction.
  double completeness = 0;
  // Fraction of reconstruction samples within the threshold of the truth.
  double precision = 0;
  // Harmonic mean 2·P·C / (P + C) of precision and completeness (0 if both 0).
  double f_score = 0;
  size_t num_recon_samples = 0;
  size_t num_truth_samples = 0;
};

// Compares `reconstruction` against `truth` (both in metres). Errors:
// InvalidArgument for bad options or when either mesh has zero surface area
// (empty, no triangles, or all triangles degenerate) — a missing
// reconstruction has no defined accuracy, so callers report it separately;
// DataLoss if a mesh fails ValidateGeometry().
StatusOr<MeshDistanceResult> ComputeMeshDistance(const Mesh& reconstruction, const Mesh& truth,
                                                 const MeshDistanceOptions& options = {});

// Distances (metres) from each of `points` to the surface in `index`, on
// `num_threads` threads; +inf for an empty index.
std::vector<float> DistancesToSurface(const std::vector<Eigen::Vector3f>& points, const TriangleIndex& index,
                                      int num_threads = 0);

// Nearest-rank percentile (`p` in (0, 100]) of `values`: the value at
// 1-based rank ceil(p/100 · n) in ascending order; 0 for no values.
double Percentile(std::vector<float> values, double p);

}  // namespace holo::metrics
