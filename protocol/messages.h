// Holoport wire protocol v1: the message header, every message type and its
// payload, and the incremental frame parser for a TCP byte stream. The
// specification is protocol/PROTOCOL.md; this file implements it.
//
// Every Decode* function is safe on untrusted input: it returns DataLoss
// (malformed, truncated, a count over its limit) or UnsupportedVersion, never
// crashes, and never allocates from an unchecked count.
#pragma once

#include <array>
#include <cstdint>
#include <deque>
#include <map>
#include <span>
#include <string>
#include <variant>
#include <vector>

#include "common/rig.h"
#include "common/status.h"

namespace holo::protocol {

// ---------------------------------------------------------------- constants

inline constexpr uint32_t kMagic = 0x54504C48;  // bytes "HLPT" on the wire
inline constexpr uint16_t kProtocolVersion = 1;
inline constexpr size_t kHeaderSize = 32;

enum class MessageType : uint16_t {
  kHello = 1,
  kWelcome = 2,
  kRefuse = 3,
  kRig = 4,
  kMeshFrame = 5,
  kColorFrame = 6,
  kAudioPose = 7,
  kClientPose = 8,
  kRenderedFrame = 9,
  kControl = 10,
  kPing = 11,
  kPong = 12,
  kStats = 13,
  kPodFrame = 14,
  kRegions = 15,
};
const char* MessageTypeName(MessageType t);
bool IsKnownMessageType(uint16_t t);

// Header flags.
inline constexpr uint16_t kFlagMoreFragments = 1u << 0;  // more fragments of this message follow
inline constexpr uint16_t kFlagKeyFrame = 1u << 1;       // decodable without earlier frames
inline constexpr uint16_t kKnownFlags = kFlagMoreFragments | kFlagKeyFrame;

// Codec identifiers (one byte on the wire; 0 is never valid).
// kG3: the surface as the signed-distance samples marching cubes reads
// (protocol/surface_codec.h). Id 3 is G2, which is not a MeshFrame codec.
enum class GeometryCodec : uint8_t { kG0 = 1, kG1 = 2, kG3 = 4 };
// kV1: per-pod inter-frame video (protocol/video_codec.h); its blobs need a
// VideoDecoder per pod stream, not DecodeColor.
enum class ColorCodec : uint8_t { kC0 = 1, kC1 = 2, kH264 = 3 /* reserved: specified, not implemented */, kV1 = 4 };
// kOpusLean: Opus in the lean AudioPose layout (PROTOCOL.md §9.1): sequence
// and capture time come from the header, the head pose is quantized.
enum class AudioCodec : uint8_t { kPcm16 = 1, kOpus = 2, kOpusLean = 3 };
// The highest audio codec id this build knows.
inline constexpr uint8_t kMaxAudioCodec = 3;
// Depth codecs of PodFrame (protocol/depth_codec.h): D1 = zstd of
// median-predicted residuals; D2 = plane-predicted residuals, context-modelled rANS.
enum class DepthCodec : uint8_t { kD1 = 1, kD2 = 2 };

// Limits every decoder enforces. The defaults are the protocol's hard limits;
// a deployment may lower them (never raise them above the defaults).
struct Limits {
  // Largest payload of one frame on the wire (one fragment), bytes.
  uint32_t max_frame_payload = 4u << 20;
  // Largest reassembled message, bytes.
  uint32_t max_message_bytes = 64u << 20;
  uint32_t max_vertices = 2u << 20;
  uint32_t max_triangles = 4u << 20;
  uint32_t max_pods = 64;
  uint32_t max_image_dim = 8192;
  // Largest decoded image, pixels (3840 × 2160 fits).
  uint32_t max_image_pixels = 8u << 20;
  uint32_t max_string = 1024;
  uint32_t max_token = 256;
  uint32_t max_stats = 256;
  Status Check() const;
};

// ---------------------------------------------------------------- header

struct Header {
  uint16_t version = kProtocolVersion;
  MessageType type = MessageType::kPing;
  uint16_t flags = 0;
  uint32_t stream_id = 0;
  uint32_t sequence = 0;
  int64_t capture_time_us = 0;
  uint32_t payload_length = 0;
  bool operator==(const Header&) const = default;
};

// Writes exactly kHeaderSize bytes.
void EncodeHeader(const Header& h, uint8_t out[kHeaderSize]);
// Decodes and validates a header from kHeaderSize bytes: DataLoss for a bad
// magic, unknown type or flags, non-zero reserved bits or a payload over
// `limits.max_frame_payload`; UnsupportedVersion ("peer speaks protocol
// version 7, this build speaks 1") for another version.
StatusOr<Header> DecodeHeader(const uint8_t* data, size_t size, const Limits& limits = {});

// ---------------------------------------------------------------- payloads

// kPod: one RGB-D pod streaming its frames to a site's pod port (§3.1).
enum class Role : uint8_t { kPublisher = 1, kViewer = 2, kRenderHost = 3, kThinClient = 4, kRecorder = 5, kPod = 6 };
const char* RoleName(Role r);

struct Capabilities {
  std::vector<GeometryCodec> geometry;
  std::vector<ColorCodec> color;
  std::vector<AudioCodec> audio;
  bool operator==(const Capabilities&) const = default;
};

struct Hello {
  Role role = Role::kViewer;
  uint16_t min_version = kProtocolVersion;
  uint16_t max_version = kProtocolVersion;
  Capabilities capabilities;
  std::string access_token;
  std::string client_name;
  bool operator==(const Hello&) const = default;
};

struct Welcome {
  uint64_t session_id = 0;
  uint16_t version = kProtocolVersion;
  GeometryCodec geometry_codec = GeometryCodec::kG1;
  ColorCodec color_codec = ColorCodec::kC1;
  AudioCodec audio_codec = AudioCodec::kOpus;
  uint32_t max_message_bytes = 64u << 20;
  std::string server_name;
  bool operator==(const Welcome&) const = default;
};

enum class RefuseReason : uint16_t {
  kUnsupportedVersion = 1,
  kBadToken = 2,
  kRoleNotAllowed = 3,
  kMalformed = 4,
  kOverloaded = 5,
  kNoCommonCodec = 6,
  kBadCalibration = 7,  // a pod whose calibration disagrees with the site's rig
};

// Frozen across protocol versions (see PROTOCOL.md) so that a peer of any
// version can read why it was refused.
struct Refuse {
  RefuseReason reason = RefuseReason::kMalformed;
  uint16_t server_min_version = kProtocolVersion;
  uint16_t server_max_version = kProtocolVersion;
  std::string message;
  bool operator==(const Refuse&) const = default;
};

struct RigMessage {
  Rig rig;
};

// Geometry of one fused frame; `data` is a self-describing geometry codec
// blob (geometry_codec.h).
struct MeshFrame {
  int64_t frame_index = 0;
  GeometryCodec codec = GeometryCodec::kG1;
  std::vector<uint8_t> data;
  bool operator==(const MeshFrame&) const = default;
};

struct PodImage {
  uint16_t pod_id = 0;
  std::vector<uint8_t> data;  // color codec blob (color_codec.h)
  bool operator==(const PodImage&) const = default;
};

// Per-pod masked colour images of one frame.
struct ColorFrame {
  int64_t frame_index = 0;
  ColorCodec codec = ColorCodec::kC1;
  std::vector<PodImage> images;
  bool operator==(const ColorFrame&) const = default;
};

// Head pose in the sender's room frame: metres and radians.
struct HeadPose {
  float x = 0, y = 0, z = 0;
  float yaw = 0, pitch = 0, roll = 0;
  bool operator==(const HeadPose&) const = default;
};

// 20 ms of one participant's audio (one Opus packet, or PCM s16 mono) plus
// where their head was. With `codec` kOpusLean the payload is the lean layout
// (PROTOCOL.md §9.1): `channels`, `sample_rate` and `duration_us_div10` are
// implied (1, 48000, 2000), `sequence` and `capture_time_us` travel in the
// protocol header (EncodeMessage / MakeWireMessage copy them there, the
// header overload of DecodePayload copies them back), and the pose is
// quantized (LeanPoseQuantum).
struct AudioPose {
  AudioCodec codec = AudioCodec::kOpus;
  uint8_t channels = 1;
  uint32_t sample_rate = 48000;
  uint16_t duration_us_div10 = 2000;  // frame duration in units of 10 µs (2000 = 20 ms)
  uint32_t sequence = 0;
  int64_t capture_time_us = 0;
  HeadPose pose;
  // Lean layout only: false = the frame carries no pose (the sender sends it
  // every other frame); `pose` is then zero and the receiver keeps the pose
  // it had (audio::JitterBuffer interpolates). Always true for codecs 1, 2.
  bool has_pose = true;
  std::vector<uint8_t> audio;
  bool operator==(const AudioPose&) const = default;
};

// The lean layout's quantization of a head pose (PROTOCOL.md §9.1): position
// in whole millimetres (i16, or i32 when a coordinate is beyond ±32.767 m),
// angles wrapped to [−π, π) in steps of 2π/65536 rad. Non-finite values
// become 0; positions are clamped to ±1 km. The result is what a receiver
// of the lean frame gets: error ≤ 0.5 mm and ≤ π/65536 rad (0.0028°) per
// angle (plus a multiple of 2π for angles outside [−π, π)).
HeadPose QuantizeLeanPose(const HeadPose& pose);
// The pose a fraction `t` of the way from `a` to `b` (t > 1 extrapolates):
// positions linearly, each angle along the shorter arc, wrapped to [−π, π].
// Receivers fill a lean frame sent without a pose with it: halfway (t = 0.5)
// between the frames before and after, or from the last two poses when the
// next frame is not there yet.
HeadPose LerpPose(const HeadPose& a, const HeadPose& b, float t);
inline HeadPose MidwayPose(const HeadPose& a, const HeadPose& b) { return LerpPose(a, b, 0.5f); }
// Bytes of a lean AudioPose payload besides the Opus packet: codec + flags
// (2), plus the pose when `has_pose` (12 bytes, 18 when a coordinate is beyond
// ±32.767 m).
size_t LeanAudioPoseOverhead(const AudioPose& frame);
// `frame` in the lean layout (codec kOpusLean) from a classic Opus frame, and
// back (lean → kOpus; a frame without pose gets `fallback_pose`). The Opus
// bytes are copied unchanged.
AudioPose ToLeanAudioPose(AudioPose frame);
AudioPose ToClassicAudioPose(AudioPose frame, const HeadPose& fallback_pose = {});

// A viewer's / thin client's head pose, sent at display rate.
struct ClientPose {
  int64_t time_us = 0;              // when the pose was sampled (client clock)
  int64_t predicted_display_us = 0; // when it is expected on screen (0 = unknown)
  std::array<float, 3> position{};           // metres, viewer's world frame
  std::array<float, 4> rotation{1, 0, 0, 0}; // unit quaternion w, x, y, z
  // Field of view as tangents of the half angles: left, right, up, down (all > 0).
  std::array<float, 4> fov_tan{1, 1, 1, 1};
  bool operator==(const ClientPose&) const = default;
};

// Render offload: one image rendered by a render host with the pose and FOV it used.
struct RenderedFrame {
  int64_t frame_index = 0;
  int64_t pose_time_us = 0;  // the ClientPose.time_us the prediction started from
  std::array<float, 3> position{};
  std::array<float, 4> rotation{1, 0, 0, 0};
  std::array<float, 4> fov_tan{1, 1, 1, 1};
  uint16_t width = 0, height = 0;
  ColorCodec codec = ColorCodec::kC1;
  std::vector<uint8_t> image;  // color codec blob
  std::vector<uint8_t> depth;  // optional: LZ4 of uint16 mm depth, empty = none
  bool operator==(const RenderedFrame&) const = default;
};

enum class ControlCommand : uint8_t {
  kSubscribe = 1,    // stream_id; value = content bits (1 geometry, 2 color, 4 audio)
  kUnsubscribe = 2,  // stream_id
  kSetQuality = 3,   // value = level 0 (lowest) .. 10 (highest)
  kPause = 4,
  kResume = 5,
  kSeek = 6,          // value = media time, µs
  kSetSpeed = 7,      // speed = playback rate (0.1 .. 8)
  kRequestKeyFrame = 8,
  kSetLoop = 9,       // value = 1 loop at the end of a replay, 0 stop there
};
// Content bits of kSubscribe / kUnsubscribe. Value 0 means 1|2|4 (not
// regions: a viewer that never heard of Regions must never receive one).
inline constexpr uint32_t kContentBitGeometry = 1;
inline constexpr uint32_t kContentBitColor = 2;
inline constexpr uint32_t kContentBitAudio = 4;
inline constexpr uint32_t kContentBitRegions = 8;
// Stats key a site sends right after Welcome (value = number of regions)
// when it publishes Regions; a viewer subscribes to kContentBitRegions only
// after seeing it, so a new viewer never sends bit 8 to an old site.
inline constexpr const char* kRegionsAnnounceKey = "site.regions";
// Stats keys a site with quality layers sends a viewer after Welcome and at
// every change of its layer: the layer it now receives (0 = full) and how
// many the site publishes (PROTOCOL.md §4, Stats).
inline constexpr const char* kLayerKey = "session.layer";
inline constexpr const char* kLayersKey = "session.layers";
// ... and how many of the site's frames the layer spans per frame it carries
// (1: every frame; 2: every other), so that a viewer does not count the
// frames a reduced layer leaves out as lost.
inline constexpr const char* kLayerStepKey = "session.layer_step";

struct Control {
  ControlCommand command = ControlCommand::kSubscribe;
  uint32_t stream_id = 0;
  int64_t value = 0;
  float speed = 1.0f;
  bool operator==(const Control&) const = default;
};

struct Ping {
  uint64_t nonce = 0;
  int64_t send_time_us = 0;
  bool operator==(const Ping&) const = default;
};

struct Pong {
  uint64_t nonce = 0;
  int64_t ping_send_time_us = 0;  // echoed
  int64_t receive_time_us = 0;    // responder's clock
  int64_t send_time_us = 0;       // responder's clock
  bool operator==(const Pong&) const = default;
};

struct Stats {
  std::vector<std::pair<std::string, double>> values;  // key ≤ 255 bytes
  bool operator==(const Stats&) const = default;
};

// One pod's RGB-D frame, pod → site (PROTOCOL.md §4 PodFrame). The capture
// time is on the POD's clock; the site maps it onto its own clock with the
// offset its pings measure.
struct PodFrame {
  uint16_t pod_id = 0;
  int64_t frame_number = 0;     // the pod's own count (0, 1, 2, ...; gaps = frames the pod dropped)
  int64_t capture_time_us = 0;  // exposure time, µs on the pod's clock
  DepthCodec depth_codec = DepthCodec::kD1;
  std::vector<uint8_t> depth;   // depth blob (depth_codec.h)
  ColorCodec color_codec = ColorCodec::kC1;
  std::vector<uint8_t> color;   // colour blob (color_codec.h)
  bool operator==(const PodFrame&) const = default;
};

// Active regions (PROTOCOL.md §4 Regions): the site's named regions and, for
// one frame, whether its reconstruction occupies each one. Sent only to
// viewers that subscribed to the regions content bit (old viewers never see
// type 15).
inline constexpr size_t kMaxRegions = 64;
inline constexpr size_t kMaxRegionName = 64;  // bytes of UTF-8
enum class RegionShape : uint8_t { kBox = 1, kSphere = 2 };
enum class RegionState : uint8_t {
  kEmpty = 0,  // not occupied
  kEnter = 1,  // occupied from this frame on (sent once per entry)
  kStay = 2,   // still occupied
  kLeave = 3,  // empty from this frame on (sent once per exit)
};
const char* RegionStateName(RegionState s);
struct RegionReport {
  std::string name;  // 1..kMaxRegionName bytes, unique within a message
  RegionShape shape = RegionShape::kBox;
  // Box: axis-aligned in the site's world frame, `a` = min corner, `b` = max
  // corner (a < b on every axis). Sphere: `a` = centre, b[0] = radius (> 0),
  // b[1] = b[2] = 0. Metres.
  std::array<float, 3> a{};
  std::array<float, 3> b{};
  RegionState state = RegionState::kEmpty;
  float occupied_litres = 0;  // reconstruction inside the region this frame (≥ 0)
  bool operator==(const RegionReport&) const = default;
};
struct Regions {
  int64_t frame_index = 0;  // the MeshFrame this report is about
  std::vector<RegionReport> regions;
  bool operator==(const Regions&) const = default;
};

using Payload = std::variant<Hello, Welcome, Refuse, RigMessage, MeshFrame, ColorFrame, AudioPose, ClientPose,
                             RenderedFrame, Control, Ping, Pong, Stats, PodFrame, Regions>;

MessageType TypeOf(const Payload& p);

// Sets `header->type` from `payload`, and for a lean AudioPose (codec
// kOpusLean) `header->sequence` and `header->capture_time_us` from the
// frame: the lean payload does not carry them. Every encoder of a whole
// message calls it (EncodeMessage, EncodeFragmented, net::MakeWireMessage).
void BindHeaderToPayload(const Payload& payload, Header* header);

// A whole message: header fields (payload_length and type are derived) + payload.
struct Message {
  Header header;
  Payload payload;
};

// Encodes `payload` (whose type sets header.type) into payload bytes.
// HOLO_CHECKs invariants the caller controls (strings within u16, etc.).
std::vector<uint8_t> EncodePayload(const Payload& payload);
// Decodes the payload bytes of a message of type `type`. Safe on untrusted input.
// A lean AudioPose decodes with sequence and capture time 0: use the overload
// below, which takes them from the header.
StatusOr<Payload> DecodePayload(MessageType type, std::span<const uint8_t> bytes, const Limits& limits = {});
// The same for the payload of a message with `header` (type from
// header.type); a lean AudioPose takes its sequence and capture time from it.
// Safe on untrusted input.
StatusOr<Payload> DecodePayload(const Header& header, std::span<const uint8_t> bytes, const Limits& limits = {});

// Header + payload in one buffer (not fragmented). `header.type` and
// `header.payload_length` are overwritten from the payload.
std::vector<uint8_t> EncodeMessage(Header header, const Payload& payload);
// Splits an encoded payload into frames of at most `fragment_bytes` payload
// each (flag kFlagMoreFragments on all but the last). Returns whole frames
// (header + fragment) concatenated per fragment.
std::vector<std::vector<uint8_t>> EncodeFragmented(Header header, const Payload& payload, size_t fragment_bytes);
// Decodes one complete unfragmented message (header + payload, nothing after).
StatusOr<Message> DecodeMessage(std::span<const uint8_t> bytes, const Limits& limits = {});

// ---------------------------------------------------------------- stream parsing

// A frame as cut from the byte stream: header + (fragment) payload.
struct Frame {
  Header header;
  std::vector<uint8_t> payload;
};

// Incremental parser for a TCP byte stream: feed whatever recv() returned
// (split or merged frames, one byte or megabytes at a time); take complete
// frames out. After the first error the stream is poisoned (the connection
// must be closed: framing is lost) and every call returns that error.
// Memory is bounded by one header + `limits.max_frame_payload`.
class FrameParser {
 public:
  explicit FrameParser(Limits limits = {}) : limits_(limits) {}
  FrameParser(const FrameParser&) = delete;
  FrameParser& operator=(const FrameParser&) = delete;

  // Consumes all of `data`. Returns the first error seen (and stays failed).
  Status Feed(const uint8_t* data, size_t size);
  // Moves the next complete frame into `out`; false if none is ready.
  bool Next(Frame* out);
  // Bytes of a frame in progress (not yet complete).
  size_t buffered() const { return header_fill_ + payload_.size(); }
  const Status& status() const { return status_; }

 private:
  Limits limits_;
  Status status_;
  uint8_t header_buf_[kHeaderSize] = {};
  size_t header_fill_ = 0;
  bool have_header_ = false;
  Header header_;
  std::vector<uint8_t> payload_;
  std::deque<Frame> ready_;
};

// Reassembles fragmented messages from frames (one message in progress per
// (stream id, type); other messages may interleave between fragments) and
// decodes complete ones. Bounded by `limits.max_message_bytes` per message
// and by `max_in_progress` messages in progress.
class MessageAssembler {
 public:
  explicit MessageAssembler(Limits limits = {}, size_t max_in_progress = 16)
      : limits_(limits), max_in_progress_(max_in_progress) {}
  // Adds a frame. Returns OK and sets `*complete` to true and fills `*out`
  // when a whole message is ready; DataLoss on any violation (a fragment
  // sequence/timestamp that does not match its first fragment, a message over
  // the limit, too many in progress, a payload that does not decode).
  Status Add(Frame&& frame, bool* complete, Message* out);

 private:
  struct Partial {
    Header first;
    std::vector<uint8_t> bytes;
  };
  Limits limits_;
  size_t max_in_progress_;
  std::map<std::pair<uint32_t, uint16_t>, Partial> partial_;
};

}  // namespace holo::protocol
