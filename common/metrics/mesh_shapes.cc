#include "common/metrics/mesh_shapes.h"

#include <cmath>
#include <cstdint>
#include <map>
#include <unordered_map>
#include <vector>
#include <utility>

#include <Eigen/Geometry>

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

Mesh MakeSdfMesh(const std::function<float(const Eigen::Vector3f&)>& sdf, const Eigen::Vector3f& lo,
                 const Eigen::Vector3i& samples, float voxel,
                 const std::function<std::array<uint8_t, 3>(const Eigen::Vector3f&, uint32_t)>& color) {
  HOLO_CHECK_MSG(samples.minCoeff() >= 2, "SDF mesh needs at least 2 samples per axis");
  HOLO_CHECK_MSG(voxel > 0, "SDF mesh voxel must be > 0");
  const int nx = samples.x(), ny = samples.y(), nz = samples.z();
  auto id = [&](int i, int j, int k) { return (static_cast<size_t>(k) * ny + j) * nx + i; };
  auto pos = [&](int i, int j, int k) { return Eigen::Vector3f(lo + voxel * Eigen::Vector3f(i, j, k)); };
  std::vector<float> val(static_cast<size_t>(nx) * ny * nz);
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) val[id(i, j, k)] = sdf(pos(i, j, k));
  Mesh m;
  std::unordered_map<uint64_t, uint32_t> edge_vertex;
  auto vertex = [&](size_t a, Eigen::Vector3f pa, size_t b, Eigen::Vector3f pb) {
    if (a > b) {  // one vertex per lattice edge, whichever tetrahedron reaches it first
      std::swap(a, b);
      std::swap(pa, pb);
    }
    const uint64_t key = (static_cast<uint64_t>(a) << 32) | b;
    if (auto it = edge_vertex.find(key); it != edge_vertex.end()) return it->second;
    const float va = val[a], vb = val[b];
    const auto idx = static_cast<uint32_t>(m.positions.size());
    m.positions.push_back(pa + (va / (va - vb)) * (pb - pa));
    m.colors.push_back(color(m.positions.back(), idx));
    edge_vertex.emplace(key, idx);
    return idx;
  };
  static constexpr int kCorner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                                        {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
  static constexpr int kTets[6][4] = {{0, 5, 1, 6}, {0, 1, 2, 6}, {0, 2, 3, 6}, {0, 3, 7, 6}, {0, 7, 4, 6}, {0, 4, 5, 6}};
  for (int k = 0; k + 1 < nz; ++k)
    for (int j = 0; j + 1 < ny; ++j)
      for (int i = 0; i + 1 < nx; ++i) {
        size_t cid[8];
        Eigen::Vector3f cp[8];
        int inside = 0;
        for (int c = 0; c < 8; ++c) {
          cid[c] = id(i + kCorner[c][0], j + kCorner[c][1], k + kCorner[c][2]);
          cp[c] = pos(i + kCorner[c][0], j + kCorner[c][1], k + kCorner[c][2]);
          inside += val[cid[c]] < 0;
        }
        if (inside == 0 || inside == 8) continue;
        for (const auto& tet : kTets) {
          std::vector<int> in, out;
          for (int c : tet) (val[cid[c]] < 0 ? in : out).push_back(c);
          if (in.empty() || out.empty()) continue;
          Eigen::Vector3f gin = Eigen::Vector3f::Zero(), gout = Eigen::Vector3f::Zero();
          for (int c : in) gin += cp[c] / static_cast<float>(in.size());
          for (int c : out) gout += cp[c] / static_cast<float>(out.size());
          const Eigen::Vector3f outward = gout - gin;
          auto emit = [&](uint32_t a, uint32_t b, uint32_t c) {
            if (a == b || b == c || a == c) return;
            const Eigen::Vector3f n = (m.positions[b] - m.positions[a]).cross(m.positions[c] - m.positions[a]);
            if (n.dot(outward) < 0) std::swap(b, c);
            m.triangles.push_back({a, b, c});
          };
          auto v = [&](int a, int b) { return vertex(cid[a], cp[a], cid[b], cp[b]); };
          if (in.size() == 1 || in.size() == 3) {
            const int s = in.size() == 1 ? in[0] : out[0];
            const std::vector<int>& o = in.size() == 1 ? out : in;
            emit(v(s, o[0]), v(s, o[1]), v(s, o[2]));
          } else {
            const uint32_t a = v(in[0], out[0]), b = v(in[0], out[1]), c = v(in[1], out[1]), d = v(in[1], out[0]);
            emit(a, b, c);
            emit(a, c, d);
          }
        }
      }
  return m;
}

}  // namespace holo::metrics
