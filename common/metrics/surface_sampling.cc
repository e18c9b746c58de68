#include "common/metrics/surface_sampling.h"

#include <algorithm>
#include <cmath>
#include <string>

#include <Eigen/Geometry>

namespace holo::metrics {
namespace {

// SplitMix64 (Steele, Lea, Flood 2014): tiny, fast and fully specified, so
// sample sets are reproducible across standard libraries.
class SplitMix64 {
 public:
  explicit SplitMix64(uint64_t seed) : state_(seed) {}
  uint64_t Next() {
    uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return z ^ (z >> 31);
  }
  // Uniform in [0, 1), 53 random bits.
  double Uniform() { return static_cast<double>(Next() >> 11) * 0x1.0p-53; }

 private:
  uint64_t state_;
};

}  // namespace

Status SamplingOptions::Check() const {
  if (!(samples_per_m2 >= 0) || !std::isfinite(samples_per_m2))
    return InvalidArgument("samples_per_m2 must be finite and >= 0, got " + std::to_string(samples_per_m2));
  if (samples_per_m2 == 0 && num_samples == 0)
    return InvalidArgument("num_samples must be > 0 when samples_per_m2 is 0");
  if (max_samples == 0) return InvalidArgument("max_samples must be > 0");
  return OkStatus();
}

size_t SampleCount(double area_m2, const SamplingOptions& options) {
  if (options.samples_per_m2 <= 0) return options.num_samples;
  const double n = std::ceil(area_m2 * options.samples_per_m2);
  if (!(n < static_cast<double>(options.max_samples))) return options.max_samples;
  return std::max<size_t>(1, static_cast<size_t>(n));
}

StatusOr<std::vector<SurfaceSample>> SampleSurface(const Mesh& mesh, const SamplingOptions& options) {
  HOLO_RETURN_IF_ERROR(options.Check());
  HOLO_RETURN_IF_ERROR(ValidateGeometry(mesh));
  std::vector<double> cdf(mesh.triangles.size());
  double total = 0;
  for (size_t t = 0; t < mesh.triangles.size(); ++t) {
    const auto& tri = mesh.triangles[t];
    const Eigen::Vector3d a = mesh.positions[tri[0]].cast<double>();
    const Eigen::Vector3d b = mesh.positions[tri[1]].cast<double>();
    const Eigen::Vector3d c = mesh.positions[tri[2]].cast<double>();
    total += 0.5 * (b - a).cross(c - a).norm();
    cdf[t] = total;
  }
  if (!(total > 0))
    return InvalidArgument("cannot sample a surface of zero area (" + std::to_string(mesh.triangles.size()) +
                           " triangles)");
  const size_t count = SampleCount(total, options);
  std::vector<SurfaceSample> samples(count);
  SplitMix64 rng(options.seed);
  for (auto& s : samples) {
    // First triangle whose cumulative area exceeds u: zero-area triangles
    // add nothing to the CDF and so can never be picked.
    const double u = rng.Uniform() * total;
    const auto it = std::upper_bound(cdf.begin(), cdf.end(), u);
    s.triangle = static_cast<uint32_t>(std::min<size_t>(it - cdf.begin(), cdf.size() - 1));
    // Uniform point in a triangle (Osada et al. 2002): with r1, r2 ~ U[0,1),
    // weights (1 − √r1, √r1 (1 − r2), √r1 r2).
    const double r1 = std::sqrt(rng.Uniform()), r2 = rng.Uniform();
    s.barycentric = Eigen::Vector3f(static_cast<float>(1 - r1), static_cast<float>(r1 * (1 - r2)),
                                    static_cast<float>(r1 * r2));
  }
  return samples;
}

Status ValidateGeometry(const Mesh& mesh) {
  const size_t n = mesh.positions.size();
  for (size_t i = 0; i < n; ++i)
    if (!mesh.positions[i].allFinite()) return DataLoss("vertex " + std::to_string(i) + " is not finite");
  for (size_t t = 0; t < mesh.triangles.size(); ++t)
    for (uint32_t idx : mesh.triangles[t])
      if (idx >= n)
        return DataLoss("triangle " + std::to_string(t) + " references vertex " + std::to_string(idx) + " of " +
                        std::to_string(n));
  return OkStatus();
}

double MeshSurfaceArea(const Mesh& mesh) {
  double area = 0;
  for (const auto& t : mesh.triangles) {
    const Eigen::Vector3d a = mesh.positions[t[0]].cast<double>();
    area += 0.5 * (mesh.positions[t[1]].cast<double>() - a).cross(mesh.positions[t[2]].cast<double>() - a).norm();
  }
  return area;
}

Eigen::Vector3f SamplePosition(const Mesh& mesh, const SurfaceSample& sample) {
  HOLO_CHECK(sample.triangle < mesh.triangles.size());
  const auto& t = mesh.triangles[sample.triangle];
  const Eigen::Vector3f& w = sample.barycentric;
  return w[0] * mesh.positions[t[0]] + w[1] * mesh.positions[t[1]] + w[2] * mesh.positions[t[2]];
}

std::vector<Eigen::Vector3f> SamplePositions(const Mesh& mesh, const std::vector<SurfaceSample>& samples) {
  std::vector<Eigen::Vector3f> out;
  out.reserve(samples.size());
  for (const auto& s : samples) out.push_back(SamplePosition(mesh, s));
  return out;
}

}  // namespace holo::metrics
