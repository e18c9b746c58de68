// Temporal geometry codec G2 (PROTOCOL.md §7.1): groups of frames that share
// one keyframe's topology.
//   keyframe  — a G1 blob (protocol/geometry_codec.h) behind a 16-byte G2 header;
//   predicted — the previous *decoded* mesh, moved in two steps: a rigid
//               motion per cluster (connected component × 9.6 cm cube of the
//               keyframe), then every vertex along its own vertex normal by
//               an integer number of displacement steps, predicted from the
//               already-decoded neighbours; all rANS-coded
//               (protocol/rans_coder.h).
// The encoder finds the motions by point-to-plane ICP (each component, then
// each of its clusters) and each displacement as the distance along ±normal
// to the new frame's mesh (a ray–plane step on the nearest triangle, twice),
// checks the two-sided point-to-surface RMS between the decoded mesh and the
// new mesh and falls back to a keyframe when that bound, the share of far
// samples, the group length or the triangle quality (keyframe area turned
// over) would break. Tangential drift is not coded: the viewer colours the
// surface from the pods' images (projective texturing), so only the shape
// has to match.
//
// Why rigid clusters: the studio's people and props move centimetres per
// frame (a bouncing ball up to ~7 cm, a forearm ~3 cm); normal displacements
// alone left 9–10 mm RMS on the studio's ground truth, with the motions
// 0.4 mm at ~1.6 KB per predicted frame (docs/codecs.md).
//
// Both sides keep the same reference in integers (positions in 1/16 of the
// keyframe's grid step) and compute normals and motions by a fixed rule
// (integer cross products; correctly rounded double +, ×, /, sqrt only), so
// the encoder's reference and the decoder's are bit-identical on every
// IEEE-754 platform (this file is compiled with -ffp-contract=off). Each
// predicted frame names its reference (keyframe id, frame counter, hash of
// the reference positions); a decoder without that exact reference refuses it.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "common/mesh.h"
#include "common/status.h"
#include "protocol/geometry_codec.h"
#include "protocol/messages.h"

namespace holo::protocol {

// The first byte of a G2 blob (G0 = 1 and G1 = 2 are the stateless codecs).
inline constexpr uint8_t kG2CodecId = 3;

struct Geometry2EncodeOptions {
  // Keyframes: G1 with these options (codec must be G1; normals are never sent,
  // the G2 decoder computes them by its own rule).
  GeometryEncodeOptions keyframe;
  // Displacement quantization step, metres; ≥ 1/16 of the keyframe step, ≤ 0.01.
  // 1 mm: ±0.5 mm rounding error along the normal.
  float displacement_step_m = 0.001f;
  // A residual (displacement minus its prediction, in steps) of magnitude below
  // this is sent as 0 (a dead zone: ≥ 0.5 rounds, larger trades error for bits).
  float dead_zone_steps = 0.5f;
  // Passes of one-ring averaging of the target displacements before they
  // are quantized (0..8): the re-fused surface's frame-to-frame ripple is
  // noise, not motion.
  int smooth_passes = 1;
  // Connected components with at least this many vertices get a rigid
  // motion (found by point-to-plane ICP) before the per-vertex displacements:
  // a ball or a prop moves centimetres per frame, far more than a vertex can
  // follow along its normal. 0 disables rigid motions.
  int rigid_min_vertices = 30;
  // The encoder searches the new surface this far along ±normal, metres; a
  // vertex with nothing closer keeps its predicted displacement.
  float max_displacement_m = 0.03f;
  // A keyframe is sent instead of a predicted frame if the predicted frame's
  // two-sided RMS distance to the input (decoded vertices to the input surface
  // and input vertices to the decoded surface) would exceed this, metres.
  float max_rms_m = 0.0013f;
  // … or if more than `max_far_fraction` of those samples are farther than
  // `far_m` (new or vanished parts, e.g. a hand coming into view).
  float far_m = 0.01f;
  float max_far_fraction = 0.01f;
  // … or if triangles holding more than this fraction of the keyframe's area
  // face away (> 90°) from their orientation in the keyframe (folds; slivers
  // that turn over weigh little).
  float max_flipped_fraction = 0.02f;
  // … or after this many frames in a group (keyframe included), 1..65535.
  int max_group_frames = 30;
  // When even the frame right after a keyframe cannot be predicted, skip the
  // (costly) attempt for the next 1, 3, 7, then 15 frames (reason "backoff")
  // until one succeeds: on content that never predicts (the per-frame fused
  // mesh, docs/codecs.md) the encoder then costs about what G1 costs.
  bool backoff = true;
  Status Check() const;
};

// What the encoder did with one frame.
struct Geometry2FrameInfo {
  bool keyframe = false;
  // Why a keyframe was sent: "first", "requested", "group-length", "rms",
  // "far", "flipped", "empty", "backoff"; "" for a predicted frame.
  std::string reason;
  uint32_t keyframe_id = 0, frame_index = 0;
  // Predicted frames: the checked two-sided error (RMS and largest distance,
  // metres), the share of far samples and of flipped (keyframe) area. The error of
  // a predicted frame that was replaced by a keyframe is reported too.
  double rms_m = 0, max_m = 0, far_fraction = 0, flipped_fraction = 0;
};

// Header fields of a G2 blob (PeekGeometry2).
struct Geometry2BlobInfo {
  bool keyframe = false;
  uint32_t keyframe_id = 0, frame_index = 0, num_vertices = 0;
};

// The reference both sides keep (internal; exposed for the encoder and the
// decoder classes only).
struct Geometry2Reference {
  bool valid = false;
  uint32_t keyframe_id = 0, frame_index = 0;
  float origin[3] = {0, 0, 0};
  float unit = 0;                                // metres per position unit (keyframe step / 16)
  std::vector<std::array<int32_t, 3>> pos;      // positions in units
  std::vector<std::array<uint32_t, 3>> triangles;
  std::vector<std::array<uint8_t, 3>> colors;   // the keyframe's (empty if none)
  std::vector<std::array<double, 3>> normals;   // unit (or zero) normals of `pos` by the G2 rule
  std::vector<uint32_t> adj_start, adj;         // neighbours (CSR) of every vertex with a smaller index
  std::vector<uint32_t> comp_start, comp_verts; // clusters (CSR of vertex lists, by first vertex)
  std::vector<uint32_t> cluster_root;           // per cluster: the smallest vertex of its connected component
  uint32_t hash = 0;                            // PROTOCOL.md §7.1 hash of `pos`
  void ToMesh(Mesh* mesh) const;
};

// Encodes a sequence of meshes (one encoder per stream). Not thread-safe;
// copies are deleted (it keeps a reference mesh and scratch buffers).
class Geometry2Encoder {
 public:
  explicit Geometry2Encoder(const Geometry2EncodeOptions& options = {});
  Geometry2Encoder(const Geometry2Encoder&) = delete;
  Geometry2Encoder& operator=(const Geometry2Encoder&) = delete;

  // InvalidArgument naming the option if `options` does not pass Check().
  Status status() const { return status_; }

  // The next Encode emits a keyframe (a new viewer, a seek, a recorder, a loss).
  void RequestKeyframe() { force_keyframe_ = true; }

  // Encodes `mesh` (must pass CheckMesh and G1's limits) as the next frame and
  // appends the blob to `out`; `info` (optional) says what was sent.
  // InvalidArgument on a bad mesh or options; the reference is then unchanged.
  Status Encode(const Mesh& mesh, std::vector<uint8_t>* out, Geometry2FrameInfo* info = nullptr);

  // The mesh a decoder holds after the last Encode (what the viewer shows).
  void DecodedMesh(Mesh* mesh) const { ref_.ToMesh(mesh); }

 private:
  Status EncodeKeyframe(const Mesh& mesh, std::vector<uint8_t>* out);
  // Codes `mesh` as a predicted frame if it meets the bounds: appends it and
  // advances the reference, or returns why a keyframe is needed (out unchanged).
  StatusOr<std::string> TryPredicted(const Mesh& mesh, std::vector<uint8_t>* out, Geometry2FrameInfo* info);

  Geometry2EncodeOptions options_;
  Status status_;
  bool force_keyframe_ = false;
  int failures_after_keyframe_ = 0, skip_left_ = 0;  // the back-off
  uint32_t next_keyframe_id_ = 1;
  Geometry2Reference ref_;
  std::vector<Eigen::Vector3f> key_face_normals_;  // the keyframe's face normals, length = twice the area
  double key_area_ = 0;                            // their summed lengths
  std::vector<uint32_t> ring_start_, ring_;        // every vertex's one-ring (CSR)
  std::vector<uint32_t> comp_clusters_start_, comp_clusters_;  // the clusters of every component (CSR)
};

// Decodes a G2 stream (one decoder per stream). Safe on untrusted input:
// DataLoss naming the field on malformed, truncated or over-limit data; a
// predicted frame whose reference this decoder does not hold (no keyframe
// yet, another keyframe id, a frame counter that skips — a lost frame — or a
// reference hash that differs) is refused with NotFound naming the
// mismatch, and the decoder keeps its reference. Every mesh it returns passes
// CheckMesh. Not thread-safe.
class Geometry2Decoder {
 public:
  Geometry2Decoder() = default;
  Geometry2Decoder(const Geometry2Decoder&) = delete;
  Geometry2Decoder& operator=(const Geometry2Decoder&) = delete;

  Status Decode(std::span<const uint8_t> blob, Mesh* mesh, const Limits& limits = {});
  bool has_reference() const { return ref_.valid; }
  // Forgets the reference: only a keyframe decodes next.
  void Reset() { ref_.valid = false; }

 private:
  Geometry2Reference ref_;
  Geometry2Reference next_;  // scratch: the reference a predicted frame builds
};

// The header of a G2 blob without decoding it (DataLoss if malformed).
StatusOr<Geometry2BlobInfo> PeekGeometry2(std::span<const uint8_t> blob);

}  // namespace holo::protocol
