// Marching-cubes case table, generated at start-up from a topological rule
// rather than typed in: for each of the 256 sign patterns of a cube's
// corners, the crossing points on the cube faces are joined into segments
// (on a face with two diagonal inside corners, each inside corner is cut off
// separately, a rule that depends on the face alone, so neighbouring cubes
// agree and the surface has no cracks), the segments are chained into closed
// loops, and each loop is triangulated as a fan.
//
// Conventions. Corner c ∈ [0, 8) sits at (c & 1, (c >> 1) & 1, (c >> 2) & 1).
// Edge e ∈ [0, 12) runs along axis a = e / 4 from its low corner
// McEdgeLowCorner(e) (bit a clear) to that corner + unit(a). A corner is
// "inside" (bit set in the case index) when its value is < 0. Triangles are
// counter-clockwise seen from the outside (values ≥ 0).
#pragma once

#include <cstdint>

namespace holo {

inline constexpr int kMcMaxTriangles = 12;

struct McCase {
  uint8_t num_triangles = 0;
  uint8_t edges[3 * kMcMaxTriangles] = {};  // three cube edges per triangle
};

// The case for `case_index` ∈ [0, 256).
const McCase& McTableCase(int case_index);
int McEdgeAxis(int edge);
int McEdgeLowCorner(int edge);

}  // namespace holo
