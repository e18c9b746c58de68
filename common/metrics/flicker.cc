#include "common/metrics/flicker.h"

#include <cmath>
#include <limits>
#include <string>

#include <Eigen/Geometry>

#include "common/worker_pool.h"
#include "common/metrics/triangle_index.h"

namespace holo::metrics {
namespace {

FlickerPairResult CompareOffsets(const std::vector<float>& a, const std::vector<float>& b) {
  HOLO_CHECK(a.size() == b.size());
  FlickerPairResult r;
  r.num_samples = a.size();
  double sum = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    if (std::isnan(a[i]) || std::isnan(b[i])) continue;
    sum += std::abs(static_cast<double>(b[i]) - static_cast<double>(a[i]));
    ++r.num_samples_used;
  }
  r.flicker_mm = r.num_samples_used > 0 ? 1000 * sum / static_cast<double>(r.num_samples_used)
                                        : std::numeric_limits<double>::quiet_NaN();
  return r;
}

Status CheckSameTopology(const Mesh& first, size_t vertices, size_t triangles, const char* what) {
  if (first.num_vertices() != vertices || first.num_triangles() != triangles)
    return InvalidArgument(std::string(what) + " has " + std::to_string(first.num_vertices()) + " vertices and " +
                           std::to_string(first.num_triangles()) + " triangles, expected " +
                           std::to_string(vertices) + " and " + std::to_string(triangles) +
                           " (the truth must keep its topology)");
  return OkStatus();
}

}  // namespace

Status FlickerOptions::Check() const {
  HOLO_RETURN_IF_ERROR(sampling.Check());
  if (!(cutoff_m > 0) || !std::isfinite(cutoff_m))
    return InvalidArgument("cutoff_m must be > 0, got " + std::to_string(cutoff_m));
  if (num_threads < 0) return InvalidArgument("num_threads must be >= 0, got " + std::to_string(num_threads));
  return OkStatus();
}

StatusOr<std::vector<float>> ComputeNormalOffsets(const Mesh& reconstruction, const Mesh& truth,
                                                  const std::vector<SurfaceSample>& samples,
                                                  const FlickerOptions& options) {
  HOLO_RETURN_IF_ERROR(options.Check());
  HOLO_RETURN_IF_ERROR(ValidateGeometry(truth));
  for (size_t i = 0; i < samples.size(); ++i)
    if (samples[i].triangle >= truth.num_triangles())
      return InvalidArgument("sample " + std::to_string(i) + " is on triangle " +
                             std::to_string(samples[i].triangle) + " but the truth has " +
                             std::to_string(truth.num_triangles()));
  HOLO_ASSIGN_OR_RETURN(const TriangleIndex index, TriangleIndex::Build(reconstruction));
  std::vector<float> offsets(samples.size(), std::numeric_limits<float>::quiet_NaN());
  const float cutoff = static_cast<float>(options.cutoff_m);
  ParallelForBlocks(samples.size(), options.num_threads, kQueriesPerBlock, [&](size_t begin, size_t end) {
    for (size_t i = begin; i < end; ++i) {
      const auto& tri = truth.triangles[samples[i].triangle];
      const Eigen::Vector3f& a = truth.positions[tri[0]];
      const Eigen::Vector3f& b = truth.positions[tri[1]];
      const Eigen::Vector3f& c = truth.positions[tri[2]];
      const Eigen::Vector3f n = (b - a).cross(c - a);
      const float len = n.norm();
      if (!(len > 0)) continue;
      const Eigen::Vector3f s = SamplePosition(truth, samples[i]);
      const ClosestPoint hit = index.Query(s, cutoff);
      if (!hit.found()) continue;
      offsets[i] = (hit.point - s).dot(n / len);
    }
  });
  return offsets;
}

StatusOr<FlickerPairResult> ComputeFlicker(const Mesh& recon_a, const Mesh& truth_a, const Mesh& recon_b,
                                           const Mesh& truth_b, const FlickerOptions& options) {
  HOLO_RETURN_IF_ERROR(options.Check());
  HOLO_RETURN_IF_ERROR(CheckSameTopology(truth_b, truth_a.num_vertices(), truth_a.num_triangles(), "truth_b"));
  HOLO_ASSIGN_OR_RETURN(const auto samples, SampleSurface(truth_a, options.sampling));
  HOLO_ASSIGN_OR_RETURN(const auto da, ComputeNormalOffsets(recon_a, truth_a, samples, options));
  HOLO_ASSIGN_OR_RETURN(const auto db, ComputeNormalOffsets(recon_b, truth_b, samples, options));
  return CompareOffsets(da, db);
}

FlickerAccumulator::FlickerAccumulator(const FlickerOptions& options) : options_(options) {}

Status FlickerAccumulator::Add(const Mesh& reconstruction, const Mesh& truth) {
  const std::string context = "flicker frame " + std::to_string(num_frames_);
  HOLO_RETURN_IF_ERROR(options_.Check());
  std::vector<SurfaceSample> drawn;
  if (num_frames_ == 0) {
    auto samples = SampleSurface(truth, options_.sampling);
    if (!samples.ok()) return samples.status().WithContext(context);
    drawn = std::move(samples).value();
  } else {
    HOLO_RETURN_IF_ERROR(CheckSameTopology(truth, truth_vertices_, truth_triangles_, "truth").WithContext(context));
  }
  auto offsets = ComputeNormalOffsets(reconstruction, truth, num_frames_ == 0 ? drawn : samples_, options_);
  if (!offsets.ok()) return offsets.status().WithContext(context);
  if (num_frames_ == 0) {
    samples_ = std::move(drawn);
    truth_vertices_ = truth.num_vertices();
    truth_triangles_ = truth.num_triangles();
  } else {
    pairs_.push_back(CompareOffsets(previous_, *offsets));
  }
  previous_ = std::move(offsets).value();
  ++num_frames_;
  return OkStatus();
}

double FlickerAccumulator::Mean() const {
  double sum = 0;
  size_t n = 0;
  for (const auto& p : pairs_) {
    if (p.num_samples_used == 0) continue;
    sum += p.flicker_mm;
    ++n;
  }
  return n > 0 ? sum / static_cast<double>(n) : std::numeric_limits<double>::quiet_NaN();
}

size_t FlickerAccumulator::num_pairs_used() const {
  size_t n = 0;
  for (const auto& p : pairs_) n += p.num_samples_used > 0 ? 1 : 0;
  return n;
}

size_t FlickerAccumulator::total_samples_used() const {
  size_t n = 0;
  for (const auto& p : pairs_) n += p.num_samples_used;
  return n;
}

}  // namespace holo::metrics
