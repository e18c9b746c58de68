// Clean-up of a fused mesh: removal of small disconnected fragments (noise
// blobs, flying-pixel debris) and optional quadric decimation to a triangle
// budget (OpenMesh's Decimater with ModQuadricT).
#pragma once

#include <cstddef>

#include "common/mesh.h"
#include "common/status.h"

namespace holo {

struct MeshCleanupOptions {
  // Connected components (triangles sharing vertices) with fewer triangles
  // than this are removed. 0 = keep everything.
  size_t min_component_triangles = 200;
  // Triangle budget for quadric decimation; 0 = no decimation. Meshes at or
  // below the budget are left as they are.
  size_t target_triangles = 0;

  Status Check() const;
};

struct MeshCleanupStats {
  size_t components = 0;          // connected components before removal
  size_t components_removed = 0;
  size_t triangles_removed = 0;   // by fragment removal
  size_t triangles_decimated = 0; // by decimation
  size_t faces_not_manifold = 0;  // faces OpenMesh refused as given (added with their own vertices)
};

// Removes small fragments and unreferenced vertices, then decimates if
// `target_triangles` > 0 (surviving vertices keep their positions, normals
// and colours: the decimater collapses half-edges). Keeps the vertex order of
// survivors. Errors: InvalidArgument for bad options, DataLoss if `mesh`
// fails Mesh::Validate().
Status CleanupMesh(const MeshCleanupOptions& options, Mesh* mesh, MeshCleanupStats* stats = nullptr);

// Drops the vertices no triangle uses (with their normals and colours),
// keeping the order of the others and renumbering the triangles.
void RemoveUnreferencedVertices(Mesh* mesh);

}  // namespace holo
