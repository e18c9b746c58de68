// The marching-cubes case table (common/marching_cubes_table.h), shared by
// the site's mesher (server/fusion/marching_cubes.cc) and the G3 geometry
// decoder (protocol/surface_codec.cc).
#include "common/marching_cubes_table.h"

#include <algorithm>

#include <Eigen/Geometry>

#include "common/status.h"

namespace holo {
namespace {

struct EdgeInfo {
  int low[12];
  int axis[12];
  EdgeInfo() {
    for (int a = 0; a < 3; ++a) {
      int k = 0;
      for (int c = 0; c < 8; ++c)
        if (!((c >> a) & 1)) {
          low[4 * a + k] = c;
          axis[4 * a + k] = a;
          ++k;
        }
    }
  }
};

const EdgeInfo& Edges() {
  static const EdgeInfo info;
  return info;
}

Eigen::Vector3f CornerPos(int c) {
  return Eigen::Vector3f(static_cast<float>(c & 1), static_cast<float>((c >> 1) & 1), static_cast<float>((c >> 2) & 1));
}

Eigen::Vector3f EdgeMid(int e) {
  return CornerPos(Edges().low[e]) + 0.5f * Eigen::Vector3f::Unit(Edges().axis[e]);
}

McCase BuildCase(int index) {
  const EdgeInfo& E = Edges();
  auto inside = [&](int c) { return ((index >> c) & 1) != 0; };
  auto crossed = [&](int e) { return inside(E.low[e]) != inside(E.low[e] | (1 << E.axis[e])); };
  int next[12];
  std::fill(next, next + 12, -1);
  int incoming[12] = {};
  for (int a = 0; a < 3; ++a) {
    for (int side = 0; side < 2; ++side) {
      const Eigen::Vector3f normal = Eigen::Vector3f::Unit(a) * (side ? 1.0f : -1.0f);
      int face_edges[4], n_face = 0;
      int cross[4], n_cross = 0;
      for (int e = 0; e < 12; ++e) {
        if (E.axis[e] == a || ((E.low[e] >> a) & 1) != side) continue;
        face_edges[n_face++] = e;
        if (crossed(e)) cross[n_cross++] = e;
      }
      HOLO_CHECK(n_face == 4);
      // Segments (from, to, reference corner on the side the segment cuts off).
      struct Segment {
        int e0, e1, ref;
      };
      Segment segs[2];
      int n_segs = 0;
      if (n_cross == 2) {
        segs[n_segs++] = {cross[0], cross[1], E.low[cross[0]]};
      } else if (n_cross == 4) {
        // Two diagonal inside corners: cut each one off on its own.
        for (int c = 0; c < 8; ++c) {
          if (((c >> a) & 1) != side || !inside(c)) continue;
          int inc[2], n_inc = 0;
          for (int e : face_edges)
            if (E.low[e] == c || (E.low[e] | (1 << E.axis[e])) == c) inc[n_inc++] = e;
          HOLO_CHECK(n_inc == 2);
          segs[n_segs++] = {inc[0], inc[1], c};
        }
        HOLO_CHECK(n_segs == 2);
      } else {
        HOLO_CHECK(n_cross == 0);
      }
      for (int k = 0; k < n_segs; ++k) {
        Segment sg = segs[k];
        // Orient so that (to − from) × face normal points to the inside side:
        // the loops then run counter-clockwise seen from outside.
        const Eigen::Vector3f p = EdgeMid(sg.e0);
        const Eigen::Vector3f d = EdgeMid(sg.e1) - p;
        const float s = d.cross(normal).dot(CornerPos(sg.ref) - p);
        HOLO_CHECK(s != 0.0f);
        if ((s > 0) != inside(sg.ref)) std::swap(sg.e0, sg.e1);
        HOLO_CHECK(next[sg.e0] == -1);
        next[sg.e0] = sg.e1;
        ++incoming[sg.e1];
      }
    }
  }
  McCase out;
  bool used[12] = {};
  for (int e = 0; e < 12; ++e) {
    HOLO_CHECK((next[e] != -1) == crossed(e));
    HOLO_CHECK(incoming[e] == (crossed(e) ? 1 : 0));
  }
  for (int start = 0; start < 12; ++start) {
    if (next[start] == -1 || used[start]) continue;
    int loop[12], n = 0;
    for (int e = start; !used[e]; e = next[e]) {
      used[e] = true;
      loop[n++] = e;
    }
    HOLO_CHECK(n >= 3);
    // Fan from the loop vertex whose fan folds least, judged on the edge
    // midpoints: the smallest cosine between a fan triangle's normal and the
    // loop's vector area (the same for every fan) is largest.
    Eigen::Vector3f area = Eigen::Vector3f::Zero();
    for (int k = 1; k + 1 < n; ++k)
      area += (EdgeMid(loop[k]) - EdgeMid(loop[0])).cross(EdgeMid(loop[k + 1]) - EdgeMid(loop[0]));
    int best_start = 0;
    float best_score = -INFINITY;
    for (int st = 0; st < n; ++st) {
      float score = INFINITY;
      const Eigen::Vector3f p0 = EdgeMid(loop[st]);
      for (int k = 1; k + 1 < n; ++k) {
        const Eigen::Vector3f nk =
            (EdgeMid(loop[(st + k) % n]) - p0).cross(EdgeMid(loop[(st + k + 1) % n]) - p0);
        score = std::min(score, nk.dot(area) / (nk.norm() * area.norm() + 1e-12f));
      }
      if (score > best_score + 1e-6f) {
        best_score = score;
        best_start = st;
      }
    }
    for (int k = 1; k + 1 < n; ++k) {
      HOLO_CHECK(out.num_triangles < kMcMaxTriangles);
      uint8_t* t = out.edges + 3 * out.num_triangles++;
      t[0] = static_cast<uint8_t>(loop[best_start]);
      t[1] = static_cast<uint8_t>(loop[(best_start + k) % n]);
      t[2] = static_cast<uint8_t>(loop[(best_start + k + 1) % n]);
    }
  }
  return out;
}

struct McTable {
  McCase cases[256];
  McTable() {
    for (int i = 0; i < 256; ++i) cases[i] = BuildCase(i);
  }
};

const McTable& Table() {
  static const McTable table;
  return table;
}

}  // namespace

const McCase& McTableCase(int case_index) { return Table().cases[case_index & 255]; }
int McEdgeAxis(int edge) { return Edges().axis[edge]; }
int McEdgeLowCorner(int edge) { return Edges().low[edge]; }

}  // namespace holo
