// Geometry codecs for MeshFrame payloads (PROTOCOL.md §7):
//   G0 — the Holoportation baseline: deduplicated vertices, fp16 positions and
//        normals, raw RGB8 colours, LZ4 on 32-bit indices.
//   G1 — our default: connectivity by a region-growing traversal (one symbol
//        per triangle: new vertex / left / right / explicit / boundary);
//        positions quantized on a grid in the frame's bounding box (default
//        step 1 mm), parallelogram-predicted along the traversal; colours in
//        YCoCg-R with chroma on a 2-level grid by default (R, G ±1, B exact),
//        predicted the same way or by the mean; normals recomputed by the
//        decoder (default) or sent octahedral 8-bit; every stream through a
//        static rANS coder, one context per component.
// Each blob is self-describing (codec id, counts, flags) and decodes without
// any other state (every frame is a key frame).
// The rANS coder is our own (a few hundred lines here): Debian packages no
// rANS/ANS library (zstd's FSE is internal to zstd), and the browser player
// (web/src/geometry.js) decodes the same streams bit for bit.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "common/mesh.h"
#include "common/status.h"
#include "protocol/messages.h"

namespace holo::protocol {

enum class NormalMode : uint8_t {
  kNone,       // the decoded mesh has no normals
  kTransmit,   // sent (G0: fp16; G1: octahedral 8+8 bits, predicted)
  kRecompute,  // G1: not sent; the decoder computes area-weighted normals from
               // the decoded triangles (G0 treats this as kTransmit)
};

struct GeometryEncodeOptions {
  GeometryCodec codec = GeometryCodec::kG1;
  // G1: position quantization step, metres. The maximum position error is
  // step/2 per axis (≤ step·√3/2 in 3D). Must be in [1e-5, 0.1].
  float position_step_m = 0.001f;
  // Normals, when the mesh has them.
  NormalMode normals = NormalMode::kRecompute;
  // Send colours when the mesh has them.
  bool colors = true;
  // G1: colour chroma (YCoCg's Co and Cg) quantized to multiples of
  // 2^chroma_shift, 0..3; 0 is lossless. R and G are then off by at most
  // 2^(chroma_shift−1) levels, B is exact.
  int chroma_shift = 1;
  Status Check() const;
};

// Encodes `mesh` (must pass Mesh::Validate) into a geometry blob appended to
// `out`. If `vertex_map` is not null it receives, for every input vertex, the
// index of the decoded vertex that represents it (UINT32_MAX if the vertex is
// dropped, e.g. unreferenced by any triangle in G1). InvalidArgument if the
// mesh is invalid or exceeds the protocol limits.
Status EncodeGeometry(const Mesh& mesh, const GeometryEncodeOptions& options, std::vector<uint8_t>* out,
                      std::vector<uint32_t>* vertex_map = nullptr);

// Decodes a geometry blob (any codec) into `mesh`. Safe on untrusted input:
// DataLoss naming the field on malformed, truncated or over-limit data; the
// result always passes Mesh::Validate.
Status DecodeGeometry(std::span<const uint8_t> blob, Mesh* mesh, const Limits& limits = {});

// The codec id of a blob without decoding it (DataLoss if too short/unknown).
StatusOr<GeometryCodec> PeekGeometryCodec(std::span<const uint8_t> blob);

// OK, or DataLoss naming the problem: attribute counts that do not match the
// vertices, a non-finite position or normal, a triangle index out of range.
// (The same checks as Mesh::Validate, kept here so that holo_protocol does
// not depend on common/mesh.cc.)
Status CheckMesh(const Mesh& mesh);
// Empties all of `mesh`'s arrays.
void ClearMesh(Mesh* mesh);

// Replaces `mesh`'s normals by normals computed from its triangles, as the G1
// decoder does when normals are flagged as recomputed (PROTOCOL.md §7): the
// area-weighted sum of face normals at each vertex, smoothed once over the
// one-ring, normalized (+Z for a vertex without a non-degenerate triangle).
void RecomputeNormals(Mesh* mesh);

// Octahedral mapping of a unit vector to [-1, 1]² and back.
void OctEncode(const Eigen::Vector3f& n, float* u, float* v);
Eigen::Vector3f OctDecode(float u, float v);

}  // namespace holo::protocol
