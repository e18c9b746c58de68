#include "common/metrics/mesh_shapes.h"

#include <cmath>
#include <cstdint>
#include <map>
#include <utility>

namespace holo::metrics {
namespace {

constexpr float kPi = 3.14159265358979323846f;

}  // namespace

Mesh MakeSphereMesh(const Eigen::Vector3f& center, float radius, int subdivisions) {
  HOLO_CHECK_MSG(radius > 0, "sphere radius must be > 0");
  HOLO_CHECK_MSG(subdivisions >= 0 && subdivisions <= 9, "sphere subdivisions must be in [0, 9]");
  // Unit-sphere directions are built in double so that vertices shared by
  // neighbouring faces are bit-identical however they are reached.
  std::vector<Eigen::Vector3d> dirs;
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  const double base[12][3] = {{-1, t, 0}, {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                              {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  for (const auto& b : base) dirs.push_back(Eigen::Vector3d(b[0], b[1], b[2]).normalized());
  std::vector<std::array<uint32_t, 3>> tris = {
      {0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
      {11, 10, 2}, {10, 7, 6}, {7, 1, 8},   {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
      {3, 8, 9},  {4, 9, 5},  {2, 4, 11},  {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<uint32_t, uint32_t>, uint32_t> midpoint;
    auto mid = [&](uint32_t a, uint32_t b) {
      const auto key = std::make_pair(std::min(a, b), std::max(a, b));
      auto it = midpoint.find(key);
      if (it != midpoint.end()) return it->second;
      const uint32_t id = static_cast<uint32_t>(dirs.size());
      dirs.push_back((dirs[a] + dirs[b]).normalized());
      midpoint.emplace(key, id);
      return id;
    };
    std::vector<std::array<uint32_t, 3>> next;
    next.reserve(tris.size() * 4);
    for (const auto& tri : tris) {
      const uint32_t ab = mid(tri[0], tri[1]), bc = mid(tri[1], tri[2]), ca = mid(tri[2], tri[0]);
      next.push_back({tri[0], ab, ca});
      next.push_back({tri[1], bc, ab});
      next.push_back({tri[2], ca, bc});
      next.push_back({ab, bc, ca});
    }
    tris = std::move(next);
  }
  Mesh mesh;
  mesh.positions.reserve(dirs.size());
  mesh.normals.reserve(dirs.size());
  for (const auto& d : dirs) {
    mesh.positions.push_back(center + (d * radius).cast<float>());
    mesh.normals.push_back(d.cast<float>());
  }
  mesh.triangles = std::move(tris);
  return mesh;
}

Mesh MakeUvSphereMesh(const Eigen::Vector3f& center, float radius, int rings, int segments) {
  HOLO_CHECK_MSG(radius > 0, "sphere radius must be > 0");
  HOLO_CHECK_MSG(rings >= 2 && segments >= 3, "UV sphere needs rings >= 2 and segments >= 3");
  Mesh mesh;
  auto add = [&](const Eigen::Vector3f& d) {
    mesh.positions.push_back(center + d * radius);
    mesh.normals.push_back(d);
  };
  add(Eigen::Vector3f(0, 0, 1));  // north pole: vertex 0
  for (int r = 1; r < rings; ++r) {
    const float theta = kPi * static_cast<float>(r) / static_cast<float>(rings);
    for (int s = 0; s < segments; ++s) {
      const float phi = 2 * kPi * static_cast<float>(s) / static_cast<float>(segments);
      add(Eigen::Vector3f(std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)));
    }
  }
  add(Eigen::Vector3f(0, 0, -1));  // south pole: last vertex
  const uint32_t south = static_cast<uint32_t>(mesh.positions.size() - 1);
  auto ring_vertex = [&](int r, int s) { return static_cast<uint32_t>(1 + (r - 1) * segments + (s % segments)); };
  for (int s = 0; s < segments; ++s) mesh.triangles.push_back({0, ring_vertex(1, s), ring_vertex(1, s + 1)});
  for (int r = 1; r + 1 < rings; ++r) {
    for (int s = 0; s < segments; ++s) {
      const uint32_t a = ring_vertex(r, s), b = ring_vertex(r, s + 1);
      const uint32_t c = ring_vertex(r + 1, s), d = ring_vertex(r + 1, s + 1);
      mesh.triangles.push_back({a, c, d});
      mesh.triangles.push_back({a, d, b});
    }
  }
  for (int s = 0; s < segments; ++s)
    mesh.triangles.push_back({south, ring_vertex(rings - 1, s + 1), ring_vertex(rings - 1, s)});
  return mesh;
}

Mesh MakePlaneMesh(const Eigen::Vector3f& center, float size_x, float size_y, int cells_x, int cells_y) {
  HOLO_CHECK_MSG(size_x > 0 && size_y > 0, "plane size must be > 0");
  HOLO_CHECK_MSG(cells_x >= 1 && cells_y >= 1, "plane needs at least one cell per axis");
  Mesh mesh;
  for (int j = 0; j <= cells_y; ++j) {
    for (int i = 0; i <= cells_x; ++i) {
      const float x = size_x * (static_cast<float>(i) / static_cast<float>(cells_x) - 0.5f);
      const float y = size_y * (static_cast<float>(j) / static_cast<float>(cells_y) - 0.5f);
      mesh.positions.push_back(center + Eigen::Vector3f(x, y, 0));
      mesh.normals.push_back(Eigen::Vector3f(0, 0, 1));
    }
  }
  const auto id = [&](int i, int j) { return static_cast<uint32_t>(j * (cells_x + 1) + i); };
  for (int j = 0; j < cells_y; ++j) {
    for (int i = 0; i < cells_x; ++i) {
      mesh.triangles.push_back({id(i, j), id(i + 1, j), id(i + 1, j + 1)});
      mesh.triangles.push_back({id(i, j), id(i + 1, j + 1), id(i, j + 1)});
    }
  }
  return mesh;
}

Mesh MakeBoxMesh(const Eigen::Vector3f& center, const Eigen::Vector3f& size, int cells) {
  HOLO_CHECK_MSG((size.array() > 0).all(), "box size must be > 0");
  HOLO_CHECK_MSG(cells >= 1, "box needs at least one cell per face edge");
  Mesh box;
  // Each face is a plane in local (u, v, n) coordinates; (u × v) = n keeps
  // the winding counter-clockwise seen from outside.
  for (int axis = 0; axis < 3; ++axis) {
    for (int sign = -1; sign <= 1; sign += 2) {
      Eigen::Vector3f n = Eigen::Vector3f::Zero();
      n[axis] = static_cast<float>(sign);
      Eigen::Vector3f u = Eigen::Vector3f::Zero(), v = Eigen::Vector3f::Zero();
      u[(axis + 1) % 3] = 1;
      v[(axis + 2) % 3] = 1;
      if (sign < 0) std::swap(u, v);
      const float su = size.dot(u), sv = size.dot(v), sn = size[axis];
      const Mesh face = MakePlaneMesh(Eigen::Vector3f::Zero(), su, sv, cells, cells);
      Mesh placed = face;
      for (size_t i = 0; i < face.positions.size(); ++i) {
        const Eigen::Vector3f& p = face.positions[i];
        placed.positions[i] = center + u * p.x() + v * p.y() + n * (0.5f * sn);
        placed.normals[i] = n;
      }
      // Appended by hand: Mesh::Append lives in common/mesh.cc, which does
      // not link at the time of writing (see surface_sampling.h).
      const uint32_t base = static_cast<uint32_t>(box.positions.size());
      box.positions.insert(box.positions.end(), placed.positions.begin(), placed.positions.end());
      box.normals.insert(box.normals.end(), placed.normals.begin(), placed.normals.end());
      for (const auto& t : placed.triangles) box.triangles.push_back({t[0] + base, t[1] + base, t[2] + base});
    }
  }
  return box;
}

}  // namespace holo::metrics
