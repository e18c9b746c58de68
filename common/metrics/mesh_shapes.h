// Simple closed and open test surfaces for tests and benchmarks. All
// generators are deterministic, emit counter-clockwise triangles seen from
// outside (for the plane: seen from +z), and fill per-vertex normals.
#pragma once

#include <array>
#include <cstdint>
#include <functional>

#include <Eigen/Core>

#include "common/mesh.h"

namespace holo::metrics {

// Icosphere: a regular icosahedron whose faces are split into four
// `subdivisions` times, vertices projected onto the sphere. It has
// 20·4^s triangles and 10·4^s + 2 vertices (s = 5: 20480 triangles,
// s = 6: 81920). `radius` in metres, must be > 0; `subdivisions` in [0, 9]
// (HOLO_CHECKed).
Mesh MakeSphereMesh(const Eigen::Vector3f& center, float radius, int subdivisions);

// UV sphere with `rings` ≥ 2 latitude bands and `segments` ≥ 3 longitude
// segments: 2·segments·(rings − 1) triangles. Poles on ±z.
Mesh MakeUvSphereMesh(const Eigen::Vector3f& center, float radius, int rings, int segments);

// Axis-aligned box with edge lengths `size` (metres, each > 0), each face
// split into `cells`×`cells` quads (`cells` ≥ 1). Faces do not share vertices,
// so normals are exact face normals.
Mesh MakeBoxMesh(const Eigen::Vector3f& center, const Eigen::Vector3f& size, int cells = 1);

// Rectangle in the plane z = center.z, `size_x` × `size_y` metres, split into
// `cells_x` × `cells_y` quads (two triangles each); normal +z.
Mesh MakePlaneMesh(const Eigen::Vector3f& center, float size_x, float size_y, int cells_x, int cells_y);

// The zero level of a signed distance function (negative inside) by marching
// tetrahedra (6 per cube) over the lattice lo + voxel·(i, j, k), 0 ≤ i <
// samples.x() and so on: one vertex per crossed lattice edge, at the linear
// zero crossing; triangles wound to face outward; colour per vertex from
// `color(position, vertex index)`. No normals (the shape of a re-extracted
// fused surface, for codec tests and benchmarks). `samples` ≥ 2 on each axis,
// `voxel` > 0 (HOLO_CHECKed).
Mesh MakeSdfMesh(const std::function<float(const Eigen::Vector3f&)>& sdf, const Eigen::Vector3f& lo,
                 const Eigen::Vector3i& samples, float voxel,
                 const std::function<std::array<uint8_t, 3>(const Eigen::Vector3f&, uint32_t)>& color);

}  // namespace holo::metrics
