// Simple closed and open test surfaces for tests and benchmarks. All
// generators are deterministic, emit counter-clockwise triangles seen from
// outside (for the plane: seen from +z), and fill per-vertex normals.
#pragma once

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

}  // namespace holo::metrics
