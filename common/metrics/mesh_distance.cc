#include "common/metrics/mesh_distance.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <thread>

#include "common/worker_pool.h"

namespace holo::metrics {
namespace {

struct DirectionStats {
  double mean = 0, max = 0, percentile = 0, within = 0;
};

DirectionStats Summarize(const std::vector<float>& d, double threshold, double percentile) {
  DirectionStats s;
  double sum = 0;
  size_t within = 0;
  float max = 0;
  for (float v : d) {
    sum += v;
    max = std::max(max, v);
    if (v <= threshold) ++within;
  }
  s.mean = sum / static_cast<double>(d.size());
  s.max = max;
  s.within = static_cast<double>(within) / static_cast<double>(d.size());
  s.percentile = Percentile(d, percentile);
  return s;
}

// One side of the comparison: its sample points and its index.
struct Prepared {
  Status status;
  std::vector<Eigen::Vector3f> points;
  TriangleIndex index;
};

Prepared Prepare(const Mesh& mesh, const SamplingOptions& sampling, bool include_vertices, const char* which) {
  Prepared out;
  auto samples = SampleSurface(mesh, sampling);
  if (!samples.ok()) {
    out.status = samples.status().WithContext(which);
    return out;
  }
  out.points = SamplePositions(mesh, *samples);
  if (include_vertices) out.points.insert(out.points.end(), mesh.positions.begin(), mesh.positions.end());
  auto index = TriangleIndex::Build(mesh);
  if (!index.ok()) {
    out.status = index.status().WithContext(which);
    return out;
  }
  out.index = std::move(index).value();
  return out;
}

}  // namespace

Status MeshDistanceOptions::Check() const {
  HOLO_RETURN_IF_ERROR(sampling.Check());
  if (!(completeness_threshold_m > 0) || !std::isfinite(completeness_threshold_m))
    return InvalidArgument("completeness_threshold_m must be > 0, got " + std::to_string(completeness_threshold_m));
  if (!(hausdorff_percentile > 0 && hausdorff_percentile <= 100))
    return InvalidArgument("hausdorff_percentile must be in (0, 100], got " + std::to_string(hausdorff_percentile));
  if (num_threads < 0) return InvalidArgument("num_threads must be >= 0, got " + std::to_string(num_threads));
  return OkStatus();
}

double Percentile(std::vector<float> values, double p) {
  if (values.empty()) return 0;
  const double rank = std::ceil(p / 100.0 * static_cast<double>(values.size()));
  const size_t k = static_cast<size_t>(std::clamp(rank, 1.0, static_cast<double>(values.size()))) - 1;
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(k), values.end());
  return values[k];
}

std::vector<float> DistancesToSurface(const std::vector<Eigen::Vector3f>& points, const TriangleIndex& index,
                                      int num_threads) {
  return index.DistanceBatch(points, std::numeric_limits<float>::infinity(), num_threads);
}

StatusOr<MeshDistanceResult> ComputeMeshDistance(const Mesh& reconstruction, const Mesh& truth,
                                                 const MeshDistanceOptions& options) {
  HOLO_RETURN_IF_ERROR(options.Check());
  SamplingOptions truth_sampling = options.sampling;
  truth_sampling.seed = options.sampling.seed + 1;
  // The two sides are independent: sample and index them concurrently.
  Prepared recon, truth_side;
  auto prepare_recon = [&] {
    recon = Prepare(reconstruction, options.sampling, options.include_vertices, "reconstruction");
  };
  auto prepare_truth = [&] { truth_side = Prepare(truth, truth_sampling, options.include_vertices, "truth"); };
  if (ResolveThreadCount(options.num_threads) > 1) {
    std::thread worker(prepare_truth);
    prepare_recon();
    worker.join();
  } else {
    prepare_recon();
    prepare_truth();
  }
  HOLO_RETURN_IF_ERROR(recon.status);
  HOLO_RETURN_IF_ERROR(truth_side.status);
  const std::vector<Eigen::Vector3f>& recon_points = recon.points;
  const std::vector<Eigen::Vector3f>& truth_points = truth_side.points;
  const TriangleIndex& recon_index = recon.index;
  const TriangleIndex& truth_index = truth_side.index;

  const std::vector<float> r2t = DistancesToSurface(recon_points, truth_index, options.num_threads);
  const std::vector<float> t2r = DistancesToSurface(truth_points, recon_index, options.num_threads);
  const DirectionStats acc = Summarize(r2t, options.completeness_threshold_m, options.hausdorff_percentile);
  const DirectionStats comp = Summarize(t2r, options.completeness_threshold_m, options.hausdorff_percentile);

  MeshDistanceResult r;
  r.accuracy_mm = 1000 * acc.mean;
  r.completeness_distance_mm = 1000 * comp.mean;
  r.chamfer_mm = 0.5 * (r.accuracy_mm + r.completeness_distance_mm);
  r.hausdorff_mm = 1000 * std::max(acc.max, comp.max);
  r.accuracy_percentile_mm = 1000 * acc.percentile;
  r.completeness_percentile_mm = 1000 * comp.percentile;
  r.hausdorff_percentile_mm = std::max(r.accuracy_percentile_mm, r.completeness_percentile_mm);
  r.precision = acc.within;
  r.completeness = comp.within;
  r.f_score = r.precision + r.completeness > 0 ? 2 * r.precision * r.completeness / (r.precision + r.completeness) : 0;
  r.num_recon_samples = recon_points.size();
  r.num_truth_samples = truth_points.size();
  return r;
}

}  // namespace holo::metrics
