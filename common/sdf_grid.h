// A signed-distance field sampled on a dense box of a regular grid: what the
// capture site hands the G3 geometry encoder (protocol/surface_codec.h) in
// place of a mesh. Marching cubes over it gives the stream mesh.
#pragma once

#include <cmath>
#include <cstddef>
#include <vector>

#include <Eigen/Core>

namespace holo {

struct SdfGrid {
  // World position (metres) of sample (0, 0, 0); sample (x, y, z) sits at
  // origin + voxel_m · (x, y, z).
  Eigen::Vector3f origin = Eigen::Vector3f::Zero();
  float voxel_m = 0;
  int nx = 0, ny = 0, nz = 0;
  // nx·ny·nz samples, x fastest: signed distance to the surface in metres,
  // positive in front (free space), negative behind; NaN = not observed.
  std::vector<float> sdf;

  size_t size() const { return static_cast<size_t>(nx) * static_cast<size_t>(ny) * static_cast<size_t>(nz); }
  size_t Index(int x, int y, int z) const {
    return static_cast<size_t>(x) + static_cast<size_t>(nx) * (static_cast<size_t>(y) + static_cast<size_t>(ny) * static_cast<size_t>(z));
  }
  bool Observed(size_t i) const { return !std::isnan(sdf[i]); }
  void Clear() {
    nx = ny = nz = 0;
    sdf.clear();
  }
};

}  // namespace holo
