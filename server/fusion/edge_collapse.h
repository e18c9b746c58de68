// Collapse of a mesh's shortest edges: a cheap first step towards a
// triangle budget.
//
// Marching cubes leaves many tiny triangles where the surface passes close
// to a grid corner. On the S8-QVGA stream mesh (16 mm grid) about 24.5 k
// triangles come out for a 20 k budget; meshoptimizer's quadric simplifier
// took 4.4–5.6 ms per frame to remove those 18 %, since its cost grows with
// the input, not with what it removes (docs/live.md). Collapsing the
// shortest edges to their midpoints removes the same triangles in a fraction
// of that, and moves the surface by at most half an edge (a few mm on a
// 16 mm grid), where the quadric simplifier would have removed these first
// anyway (their error is the smallest).
//
// An edge is collapsed only if the mesh stays as it was around it:
//  * both ends are interior manifold vertices (their triangles form one
//    closed fan) and the edge has exactly two triangles;
//  * the link condition holds: the ends share no neighbour other than the
//    two opposite vertices, and not both have only three triangles, so no
//    edge gets more than two triangles and no triangle is duplicated (a
//    closed mesh stays closed);
//  * no surviving triangle around it flips or degenerates.
// A pass takes the shortest candidates in order and updates the mesh after
// every collapse (triangles renamed, the edge's two removed, the fans
// merged), so the tests above always see the current mesh; another pass
// runs only if the first ran out of candidates before the budget, up to
// `max_passes`.
#pragma once

#include <cstddef>

#include "common/mesh.h"

namespace holo {

struct EdgeCollapseOptions {
  size_t target_triangles = 0;  // stop at or below this many triangles
  float max_edge_m = 0.004f;    // only edges shorter than this collapse
  int max_passes = 4;
};

struct EdgeCollapseStats {
  size_t collapses = 0;
  int passes = 0;
  float longest_collapsed_m = 0;
};

// Collapses edges of `mesh` (shortest first) until it has at most
// `target_triangles` triangles or no allowed edge below `max_edge_m` is left.
// Normals (renormalized) and colours of the two ends are averaged; unused
// vertices are removed at the end (survivors keep their order). The mesh
// must be valid (Mesh::Validate).
void CollapseShortEdges(const EdgeCollapseOptions& options, Mesh* mesh, EdgeCollapseStats* stats = nullptr);

}  // namespace holo
