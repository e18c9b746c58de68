// Deterministic, area-weighted random points on a triangle mesh surface.
//
// A sample is stored as (triangle, barycentric) rather than a position so
// that it can be carried along with a deforming mesh of the same topology
// (the temporal flicker metric relies on this).
#pragma once

#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "common/mesh.h"
#include "common/status.h"

namespace holo::metrics {

struct SurfaceSample {
  uint32_t triangle = 0;                                 // index into Mesh::triangles
  Eigen::Vector3f barycentric = Eigen::Vector3f::Zero();  // weights of vertices 0, 1, 2; sum 1
};

struct SamplingOptions {
  // Number of samples when `samples_per_m2` is 0.
  size_t num_samples = 100000;
  // If > 0: the count is ceil(surface area in m² × samples_per_m2) instead.
  double samples_per_m2 = 0;
  // Upper bound on the count from `samples_per_m2` (protects against huge
  // meshes or units mistakes).
  size_t max_samples = 10'000'000;
  // Seed of the generator; the same mesh, options and seed give the same
  // samples on every platform (the generator is SplitMix64, implemented here,
  // not a std:: distribution).
  uint64_t seed = 1;

  // OK, or InvalidArgument naming the bad field.
  Status Check() const;
};

// Number of samples `options` asks for on a surface of `area_m2`.
size_t SampleCount(double area_m2, const SamplingOptions& options);

// Samples the surface of `mesh` uniformly by area: a triangle is chosen with
// probability proportional to its area, then a point uniformly inside it.
// Triangles of zero area are never chosen. Errors: InvalidArgument for bad
// options or a mesh whose total area is zero (no triangles, or all
// degenerate); DataLoss from ValidateGeometry().
StatusOr<std::vector<SurfaceSample>> SampleSurface(const Mesh& mesh, const SamplingOptions& options);

// OK, or DataLoss naming the first triangle index out of range or the first
// non-finite position. Normals and colours are not looked at. (The metrics
// use this instead of Mesh::Validate() so that they do not depend on
// common/mesh.cc; see MeshSurfaceArea.)
Status ValidateGeometry(const Mesh& mesh);

// Total surface area of `mesh`'s triangles, m², summed in double precision.
// (Use this rather than Mesh::SurfaceArea(), which does not link at the time
// of writing: common/mesh.cc lacks <Eigen/Geometry> for cross().)
double MeshSurfaceArea(const Mesh& mesh);

// Position of `sample` on `mesh` (which must have the topology the sample was
// drawn on; HOLO_CHECKs the triangle index).
Eigen::Vector3f SamplePosition(const Mesh& mesh, const SurfaceSample& sample);

// Positions of all samples.
std::vector<Eigen::Vector3f> SamplePositions(const Mesh& mesh, const std::vector<SurfaceSample>& samples);

}  // namespace holo::metrics
