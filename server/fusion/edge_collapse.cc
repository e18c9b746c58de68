#include "server/fusion/edge_collapse.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <vector>

#include <Eigen/Geometry>

#include "server/fusion/mesh_cleanup.h"

namespace holo {
namespace {

constexpr int kMaxFan = 32;  // vertices with more triangles are left alone

struct Candidate {
  float len2;
  uint32_t a, b;
};

// The triangles around every vertex (compressed rows, built once per pass)
// and, as the pass collapses edges, what changed since: triangles that died
// and the vertices merged into each survivor (its fan is theirs together).
struct Fans {
  std::vector<uint32_t> start, tris;
  std::vector<uint8_t> dead;          // per triangle
  std::vector<uint32_t> parent;       // merged vertex → survivor (itself if alive)
  std::vector<uint32_t> next_merged;  // chain of the vertices merged into a survivor
  static constexpr uint32_t kEnd = 0xFFFFFFFFu;

  void Build(const std::vector<std::array<uint32_t, 3>>& t, size_t nv) {
    start.assign(nv + 1, 0);
    for (const auto& tri : t) {
      for (uint32_t v : tri) ++start[v + 1];
    }
    for (size_t v = 0; v < nv; ++v) start[v + 1] += start[v];
    tris.resize(start[nv]);
    std::vector<uint32_t> cursor(start.begin(), start.end() - 1);
    for (size_t i = 0; i < t.size(); ++i) {
      for (uint32_t v : t[i]) tris[cursor[v]++] = static_cast<uint32_t>(i);
    }
    dead.assign(t.size(), 0);
    parent.resize(nv);
    std::iota(parent.begin(), parent.end(), 0u);
    next_merged.assign(nv, kEnd);
  }
  uint32_t Find(uint32_t v) {
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  }
  // Calls fn(t) for every live triangle around survivor v.
  template <typename F>
  void ForEachTriangle(uint32_t v, F&& fn) const {
    for (uint32_t u = v; u != kEnd; u = next_merged[u]) {
      for (uint32_t i = start[u]; i < start[u + 1]; ++i) {
        if (!dead[tris[i]]) fn(tris[i]);
      }
    }
  }
};

// The one-ring of survivor `v` if its live triangles form a single closed
// fan: `ring` gets the neighbours (each once), `fan` the triangles. False
// otherwise (boundary, non-manifold or pinched vertex, or more than kMaxFan
// triangles).
bool ClosedFan(uint32_t v, const std::vector<std::array<uint32_t, 3>>& t, const Fans& fans,
               std::array<uint32_t, kMaxFan>* ring, std::array<uint32_t, kMaxFan>* fan, int* size) {
  int n = 0;
  bool overflow = false;
  fans.ForEachTriangle(v, [&](uint32_t tri) {
    if (n < kMaxFan) {
      (*fan)[n++] = tri;
    } else {
      overflow = true;
    }
  });
  if (overflow || n < 3) return false;
  // Each triangle seen from v: (next, after) counter-clockwise.
  std::array<uint32_t, kMaxFan> next{}, after{};
  for (int i = 0; i < n; ++i) {
    const auto& tri = t[(*fan)[i]];
    const int k = tri[0] == v ? 0 : tri[1] == v ? 1 : 2;
    next[i] = tri[(k + 1) % 3];
    after[i] = tri[(k + 2) % 3];
  }
  // Walk around: from triangle i the next one starts where i ends. A single
  // closed fan visits every triangle once and comes back to the first.
  int i = 0;
  for (int step = 0; step < n; ++step) {
    (*ring)[step] = next[i];
    int j = -1;
    for (int c = 0; c < n; ++c) {
      if (next[c] == after[i]) {
        if (j >= 0) return false;  // two triangles continue here: not a simple fan
        j = c;
      }
    }
    if (j < 0) return false;  // boundary
    i = j;
    if (i == 0 && step + 1 < n) return false;  // closed early: v is pinched
  }
  if (i != 0) return false;
  // Every neighbour once (a repeated one would mean a fold in the fan).
  std::array<uint32_t, kMaxFan> sorted = *ring;
  std::sort(sorted.begin(), sorted.begin() + n);
  if (std::adjacent_find(sorted.begin(), sorted.begin() + n) != sorted.begin() + n) return false;
  *size = n;
  return true;
}

Eigen::Vector3f Normal(const Eigen::Vector3f& p0, const Eigen::Vector3f& p1, const Eigen::Vector3f& p2) {
  return (p1 - p0).cross(p2 - p0);
}

}  // namespace

void CollapseShortEdges(const EdgeCollapseOptions& options, Mesh* mesh, EdgeCollapseStats* stats) {
  EdgeCollapseStats local;
  EdgeCollapseStats& st = stats ? *stats : local;
  st = EdgeCollapseStats{};
  auto& pos = mesh->positions;
  auto& tris = mesh->triangles;
  const size_t nv = pos.size();
  const bool has_normals = mesh->normals.size() == nv, has_colors = mesh->colors.size() == nv;
  const float max2 = options.max_edge_m * options.max_edge_m;
  Fans fans;
  std::vector<Candidate> cands;
  for (int pass = 0; pass < options.max_passes && tris.size() > options.target_triangles; ++pass) {
    const size_t nt = tris.size();
    const size_t need = (nt - options.target_triangles + 1) / 2;  // an interior collapse removes 2
    cands.clear();
    for (const auto& tri : tris) {
      for (int k = 0; k < 3; ++k) {
        const uint32_t a = tri[k], b = tri[(k + 1) % 3];
        if (a >= b) continue;  // each interior edge once (its other triangle has it as b → a)
        const float len2 = (pos[a] - pos[b]).squaredNorm();
        if (len2 < max2) cands.push_back({len2, a, b});
      }
    }
    if (cands.empty()) break;
    // The shortest ones, with room for those refused below.
    auto shorter = [](const Candidate& x, const Candidate& y) {
      return x.len2 < y.len2 || (x.len2 == y.len2 && (x.a < y.a || (x.a == y.a && x.b < y.b)));
    };
    const size_t keep = std::min(cands.size(), 2 * need + 64);
    if (keep < cands.size()) {
      std::nth_element(cands.begin(), cands.begin() + static_cast<std::ptrdiff_t>(keep), cands.end(), shorter);
      cands.resize(keep);
    }
    std::sort(cands.begin(), cands.end(), shorter);
    // One pass over the candidates, the mesh updated after each collapse
    // (triangles renamed, two marked dead, the fans merged), so the tests
    // always see the current mesh.
    fans.Build(tris, nv);
    size_t done = 0;
    std::array<uint32_t, kMaxFan> ring_a{}, ring_b{}, fan_a{}, fan_b{};
    for (const Candidate& c : cands) {
      const uint32_t a = fans.Find(c.a), b = fans.Find(c.b);
      if (a == b) continue;
      const float len2 = (pos[a] - pos[b]).squaredNorm();  // ends may have moved
      if (!(len2 < max2)) continue;
      int na = 0, nb = 0;
      if (!ClosedFan(a, tris, fans, &ring_a, &fan_a, &na) || !ClosedFan(b, tris, fans, &ring_b, &fan_b, &nb)) continue;
      // Link condition: in closed fans the edge has two triangles, whose
      // opposite corners are common neighbours; there must be no other.
      int common = 0;
      for (int i = 0; i < na; ++i) {
        common += static_cast<int>(std::find(ring_b.begin(), ring_b.begin() + nb, ring_a[i]) != ring_b.begin() + nb);
      }
      if (common != 2) continue;
      // The two opposite corners are also joined by an edge of a's and of
      // b's fan only when both have three triangles (a tetrahedron's tip):
      // the collapse would leave two copies of one triangle. The merged
      // vertex keeps na + nb − 4 triangles; it needs three.
      if (na + nb < 7) continue;
      // No triangle that survives may flip or collapse to a sliver.
      const Eigen::Vector3f mid = 0.5f * (pos[a] + pos[b]);
      bool ok = true;
      for (int side = 0; side < 2 && ok; ++side) {
        const auto& fan = side == 0 ? fan_a : fan_b;
        const int n = side == 0 ? na : nb;
        for (int i = 0; i < n && ok; ++i) {
          const auto& tri = tris[fan[i]];
          const bool has_a = tri[0] == a || tri[1] == a || tri[2] == a;
          const bool has_b = tri[0] == b || tri[1] == b || tri[2] == b;
          if (has_a && has_b) continue;  // removed by the collapse
          Eigen::Vector3f p[3], q[3];
          for (int k = 0; k < 3; ++k) {
            p[k] = pos[tri[k]];
            q[k] = tri[k] == a || tri[k] == b ? mid : p[k];
          }
          const Eigen::Vector3f before = Normal(p[0], p[1], p[2]), after = Normal(q[0], q[1], q[2]);
          // Same side, and at most ~60° of turn.
          ok = after.dot(before) > 0.5f * after.norm() * before.norm() && after.squaredNorm() > 0.0f;
        }
      }
      if (!ok) continue;
      pos[a] = mid;
      if (has_normals) {
        const Eigen::Vector3f n = mesh->normals[a] + mesh->normals[b];
        const float len = n.norm();
        mesh->normals[a] = len > 0 ? Eigen::Vector3f(n / len) : mesh->normals[a];
      }
      if (has_colors) {
        for (int ch = 0; ch < 3; ++ch) {
          mesh->colors[a][ch] = static_cast<uint8_t>((mesh->colors[a][ch] + mesh->colors[b][ch] + 1) / 2);
        }
      }
      // The edge's two triangles die; b's others now use a.
      for (int i = 0; i < nb; ++i) {
        auto& tri = tris[fan_b[i]];
        const bool has_a = tri[0] == a || tri[1] == a || tri[2] == a;
        if (has_a) {
          fans.dead[fan_b[i]] = 1;
          continue;
        }
        for (uint32_t& v : tri) v = v == b ? a : v;
      }
      fans.parent[b] = a;
      uint32_t tail = a;
      while (fans.next_merged[tail] != Fans::kEnd) tail = fans.next_merged[tail];
      fans.next_merged[tail] = b;
      st.longest_collapsed_m = std::max(st.longest_collapsed_m, std::sqrt(len2));
      if (++done >= need) break;
    }
    if (done == 0) break;
    size_t out = 0;
    for (size_t t = 0; t < nt; ++t) {
      if (!fans.dead[t]) tris[out++] = tris[t];
    }
    tris.resize(out);
    st.collapses += done;
    st.passes = pass + 1;
  }
  if (st.collapses > 0) RemoveUnreferencedVertices(mesh);
}

}  // namespace holo
