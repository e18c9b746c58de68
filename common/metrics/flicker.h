// Temporal flicker: the frame-to-frame change of a reconstructed surface that
// the true motion does not explain. Definition: docs/metrics.md §Flicker.
//
// Fixed samples (triangle, barycentric) are drawn once on the ground-truth
// mesh, which keeps its vertices and triangles every frame (skinned), so each
// sample follows the true motion. At frame t the offset d_t(s) is the signed
// distance from the truth point s to the nearest reconstruction point r,
// measured along the truth face normal n_s: d_t(s) = (r − s)·n_s, valid if
// |r − s| ≤ cutoff. flicker(t, t+1) = mean over samples valid in both frames
// of |d_{t+1}(s) − d_t(s)|, in millimetres.
#pragma once

#include <cstddef>
#include <vector>

#include "common/mesh.h"
#include "common/metrics/surface_sampling.h"
#include "common/status.h"

namespace holo::metrics {

struct FlickerOptions {
  // Samples on the truth surface (drawn on the first truth mesh).
  SamplingOptions sampling = {.num_samples = 20000};
  // A sample whose nearest reconstruction point is farther than this
  // (metres) is invalid in that frame (hole, or not this surface).
  double cutoff_m = 0.02;
  // Worker threads for the closest-point queries; 0 = all cores.
  int num_threads = 0;

  // OK, or InvalidArgument naming the bad field.
  Status Check() const;
};

// Signed offsets d(s) in metres, one per sample, NaN where the sample is
// invalid (no reconstruction within the cutoff, or the truth triangle is
// degenerate in this frame). An empty `reconstruction` gives all NaN.
// Errors: InvalidArgument if a sample's triangle is not in `truth`; DataLoss
// from ValidateGeometry().
StatusOr<std::vector<float>> ComputeNormalOffsets(const Mesh& reconstruction, const Mesh& truth,
                                                  const std::vector<SurfaceSample>& samples,
                                                  const FlickerOptions& options = {});

struct FlickerPairResult {
  // Mean |d_{t+1} − d_t| over samples valid in both frames, mm; NaN if
  // no sample is valid in both.
  double flicker_mm = 0;
  size_t num_samples_used = 0;  // valid in both frames
  size_t num_samples = 0;       // drawn
};

// Flicker between two consecutive frames. `truth_a` and `truth_b` must have
// the same vertex and triangle counts (InvalidArgument otherwise, also for a
// truth of zero area); samples are drawn on `truth_a`.
StatusOr<FlickerPairResult> ComputeFlicker(const Mesh& recon_a, const Mesh& truth_a, const Mesh& recon_b,
                                           const Mesh& truth_b, const FlickerOptions& options = {});

// Flicker over a sequence: call Add() once per frame in order. Samples are
// drawn on the first truth mesh and reused for every frame.
class FlickerAccumulator {
 public:
  explicit FlickerAccumulator(const FlickerOptions& options = {});
  FlickerAccumulator(const FlickerAccumulator&) = delete;
  FlickerAccumulator& operator=(const FlickerAccumulator&) = delete;

  // Adds frame t. Errors (the frame is then not added): bad options, a truth
  // mesh whose vertex or triangle count differs from the first frame's, a
  // first truth mesh of zero area, invalid meshes. An empty reconstruction is
  // accepted (all samples invalid in that frame).
  Status Add(const Mesh& reconstruction, const Mesh& truth);

  // Mean of flicker_mm over all consecutive pairs that had at least one
  // sample valid in both frames (each such pair weighs the same); NaN if
  // there is none.
  double Mean() const;
  // Per-pair results, pair i = frames (i, i+1).
  const std::vector<FlickerPairResult>& pairs() const { return pairs_; }
  size_t num_frames() const { return num_frames_; }
  // Pairs that contributed to Mean().
  size_t num_pairs_used() const;
  // Sum over pairs of samples valid in both frames.
  size_t total_samples_used() const;
  // Samples drawn (0 before the first Add()).
  size_t num_samples() const { return samples_.size(); }

 private:
  FlickerOptions options_;
  std::vector<SurfaceSample> samples_;
  size_t truth_vertices_ = 0, truth_triangles_ = 0;
  std::vector<float> previous_;  // offsets of the last frame
  std::vector<FlickerPairResult> pairs_;
  size_t num_frames_ = 0;
};

}  // namespace holo::metrics
