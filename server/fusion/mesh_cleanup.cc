#include "server/fusion/mesh_cleanup.h"

#include <algorithm>
#include <numeric>
#include <vector>

#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>
#include <OpenMesh/Core/System/omstream.hh>
#include <OpenMesh/Tools/Decimater/DecimaterT.hh>
#include <OpenMesh/Tools/Decimater/ModQuadricT.hh>

namespace holo {
namespace {

using OMesh = OpenMesh::TriMesh_ArrayKernelT<>;

// Root of `v`, halving the path on the way. Roots are linked under the
// smallest root of a union, so every parent index is ≤ its child's.
inline uint32_t FindRoot(uint32_t* parent, uint32_t v) {
  while (parent[v] != v) {
    const uint32_t g = parent[parent[v]];
    parent[v] = g;
    v = g;
  }
  return v;
}

// Buffers reused across calls on the same thread (no per-frame heap churn).
struct CleanupScratch {
  std::vector<uint32_t> parent, count, remap;
  std::vector<uint8_t> keep;
};

CleanupScratch& ThreadScratch() {
  thread_local CleanupScratch scratch;
  return scratch;
}

// Keeps the triangles for which keep[t] is true and the vertices they use,
// preserving order.
void Compact(const std::vector<uint8_t>& keep, std::vector<uint32_t>& remap, Mesh* mesh) {
  const size_t nv = mesh->positions.size();
  remap.assign(nv, UINT32_MAX);
  size_t out_t = 0;
  for (size_t t = 0; t < mesh->triangles.size(); ++t) {
    if (!keep[t]) continue;
    for (uint32_t v : mesh->triangles[t]) remap[v] = 0;
    mesh->triangles[out_t++] = mesh->triangles[t];
  }
  mesh->triangles.resize(out_t);
  uint32_t next = 0;
  for (size_t v = 0; v < nv; ++v) {
    if (remap[v] == UINT32_MAX) continue;
    remap[v] = next;
    mesh->positions[next] = mesh->positions[v];
    if (!mesh->normals.empty()) mesh->normals[next] = mesh->normals[v];
    if (!mesh->colors.empty()) mesh->colors[next] = mesh->colors[v];
    ++next;
  }
  mesh->positions.resize(next);
  if (!mesh->normals.empty()) mesh->normals.resize(next);
  if (!mesh->colors.empty()) mesh->colors.resize(next);
  for (auto& tri : mesh->triangles)
    for (uint32_t& v : tri) v = remap[v];
}

Status Decimate(size_t target, Mesh* mesh, MeshCleanupStats* stats) {
  OMesh om;
  om.request_vertex_status();
  om.request_edge_status();
  om.request_face_status();
  OpenMesh::VPropHandleT<uint32_t> source;
  om.add_property(source);
  om.reserve(mesh->positions.size(), 3 * mesh->triangles.size() / 2, mesh->triangles.size());
  std::vector<OMesh::VertexHandle> handles(mesh->positions.size());
  for (size_t v = 0; v < mesh->positions.size(); ++v) {
    const Eigen::Vector3f& p = mesh->positions[v];
    handles[v] = om.add_vertex(OMesh::Point(p.x(), p.y(), p.z()));
    om.property(source, handles[v]) = static_cast<uint32_t>(v);
  }
  // OpenMesh reports every refused face on its error stream; we count them instead.
  const bool err_was_enabled = omerr().is_enabled();
  omerr().disable();
  for (const auto& tri : mesh->triangles) {
    const OMesh::FaceHandle f = om.add_face(handles[tri[0]], handles[tri[1]], handles[tri[2]]);
    if (f.is_valid()) continue;
    // Non-manifold here (OpenMesh refuses it): give the face its own copies
    // of the vertices so it survives, detached.
    ++stats->faces_not_manifold;
    OMesh::VertexHandle copy[3];
    for (int k = 0; k < 3; ++k) {
      copy[k] = om.add_vertex(om.point(handles[tri[k]]));
      om.property(source, copy[k]) = tri[k];
    }
    (void)om.add_face(copy[0], copy[1], copy[2]);
  }
  if (err_was_enabled) omerr().enable();
  OpenMesh::Decimater::DecimaterT<OMesh> decimater(om);
  OpenMesh::Decimater::ModQuadricT<OMesh>::Handle quadric;
  decimater.add(quadric);
  decimater.module(quadric).unset_max_err();
  if (!decimater.initialize()) return Internal("OpenMesh decimater failed to initialise");
  decimater.decimate_to_faces(0, target);
  om.garbage_collection();

  Mesh result;
  result.positions.reserve(om.n_vertices());
  const bool has_normals = !mesh->normals.empty(), has_colors = !mesh->colors.empty();
  for (const auto& vh : om.vertices()) {
    const uint32_t src = om.property(source, vh);
    const OMesh::Point& p = om.point(vh);
    result.positions.emplace_back(p[0], p[1], p[2]);
    if (has_normals) result.normals.push_back(mesh->normals[src]);
    if (has_colors) result.colors.push_back(mesh->colors[src]);
  }
  result.triangles.reserve(om.n_faces());
  for (const auto& fh : om.faces()) {
    std::array<uint32_t, 3> tri;
    int k = 0;
    for (const auto& vh : om.fv_range(fh)) {
      if (k < 3) tri[static_cast<size_t>(k)] = static_cast<uint32_t>(vh.idx());
      ++k;
    }
    if (k == 3) result.triangles.push_back(tri);
  }
  stats->triangles_decimated = mesh->triangles.size() - std::min(mesh->triangles.size(), result.triangles.size());
  *mesh = std::move(result);
  return OkStatus();
}

}  // namespace

Status MeshCleanupOptions::Check() const { return OkStatus(); }

Status CleanupMesh(const MeshCleanupOptions& options, Mesh* mesh, MeshCleanupStats* stats) {
  HOLO_RETURN_IF_ERROR(options.Check().WithContext("MeshCleanupOptions"));
  HOLO_RETURN_IF_ERROR(mesh->Validate());
  MeshCleanupStats local;
  if (!stats) stats = &local;
  *stats = {};
  if (mesh->triangles.empty()) return OkStatus();

  // Components by union-find over the vertices of each triangle: each
  // triangle links the roots of its three vertices under the smallest, so
  // parent[v] ≤ v throughout and one pass in index order flattens every
  // tree (the parent's root is already final when v is reached).
  CleanupScratch& sc = ThreadScratch();
  const size_t nv = mesh->positions.size(), nt = mesh->triangles.size();
  sc.parent.resize(nv);
  uint32_t* parent = sc.parent.data();
  std::iota(parent, parent + nv, 0u);
  for (const auto& tri : mesh->triangles) {
    const uint32_t a = FindRoot(parent, tri[0]), b = FindRoot(parent, tri[1]), c = FindRoot(parent, tri[2]);
    const uint32_t r = std::min(a, std::min(b, c));
    parent[a] = r;
    parent[b] = r;
    parent[c] = r;
  }
  for (size_t v = 0; v < nv; ++v) parent[v] = parent[parent[v]];
  sc.count.assign(nv, 0u);
  uint32_t* count = sc.count.data();
  for (const auto& tri : mesh->triangles) ++count[parent[tri[0]]];
  for (size_t v = 0; v < nv; ++v) {
    if (count[v] == 0) continue;
    ++stats->components;
    if (count[v] < options.min_component_triangles) ++stats->components_removed;
  }
  if (stats->components_removed == 0) {
    // Nothing to remove: the mesh stays as it is (every vertex of a
    // marching-cubes mesh is referenced).
    bool all_used = true;
    for (size_t v = 0; v < nv && all_used; ++v) all_used = count[parent[v]] > 0;
    if (!all_used) {
      sc.keep.assign(nt, 1);
      Compact(sc.keep, sc.remap, mesh);
    }
  } else {
    sc.keep.resize(nt);
    for (size_t t = 0; t < nt; ++t) {
      sc.keep[t] = count[parent[mesh->triangles[t][0]]] >= options.min_component_triangles;
      stats->triangles_removed += !sc.keep[t];
    }
    Compact(sc.keep, sc.remap, mesh);
  }

  if (options.target_triangles > 0 && mesh->triangles.size() > options.target_triangles)
    HOLO_RETURN_IF_ERROR(Decimate(options.target_triangles, mesh, stats));
  return OkStatus();
}

void RemoveUnreferencedVertices(Mesh* mesh) {
  CleanupScratch& s = ThreadScratch();
  s.keep.assign(mesh->triangles.size(), 1);
  Compact(s.keep, s.remap, mesh);
}

}  // namespace holo
