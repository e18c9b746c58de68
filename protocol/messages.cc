#include "protocol/messages.h"

#include <algorithm>
#include <cmath>
#include <cstring>

#include "protocol/byte_io.h"

namespace holo::protocol {
namespace {

// ---------------------------------------------------------------- shared pieces

template <typename E>
void WriteCodecList(ByteWriter& w, const std::vector<E>& v) {
  HOLO_CHECK(v.size() <= 16);
  w.U8(static_cast<uint8_t>(v.size()));
  for (E e : v) w.U8(static_cast<uint8_t>(e));
}

template <typename E>
Status ReadCodecList(ByteReader& r, const char* field, uint8_t max_id, std::vector<E>* v) {
  uint8_t n = 0;
  HOLO_RETURN_IF_ERROR(r.U8(field, &n));
  if (n > 16) return DataLoss(std::string(field) + ": " + Str(n) + " codecs, at most 16");
  HOLO_RETURN_IF_ERROR(r.CheckCount(field, n, 1));
  v->clear();
  for (int i = 0; i < n; ++i) {
    uint8_t id = 0;
    HOLO_RETURN_IF_ERROR(r.U8(field, &id));
    // Unknown codec ids from a newer peer are skipped, not refused.
    if (id >= 1 && id <= max_id) v->push_back(static_cast<E>(id));
  }
  return OkStatus();
}

void WritePose(ByteWriter& w, const Pose& p) {
  const Eigen::Matrix3f r = p.linear();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) w.F32(r(i, j));
  for (int i = 0; i < 3; ++i) w.F32(p.translation()[i]);
}

Status ReadPose(ByteReader& r, const char* field, Pose* p) {
  Eigen::Matrix3f m;
  Eigen::Vector3f t;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) HOLO_RETURN_IF_ERROR(r.F32(field, &m(i, j)));
  for (int i = 0; i < 3; ++i) HOLO_RETURN_IF_ERROR(r.F32(field, &t[i]));
  if ((m.transpose() * m - Eigen::Matrix3f::Identity()).cwiseAbs().maxCoeff() > 1e-3f || m.determinant() < 0.5f) {
    return DataLoss(std::string(field) + ": rotation is not orthonormal");
  }
  *p = Pose::Identity();
  p->linear() = m;
  p->translation() = t;
  return OkStatus();
}

void WriteIntrinsics(ByteWriter& w, const Intrinsics& in) {
  w.U32(static_cast<uint32_t>(in.width));
  w.U32(static_cast<uint32_t>(in.height));
  w.F64(in.fx);
  w.F64(in.fy);
  w.F64(in.cx);
  w.F64(in.cy);
  for (double d : in.distortion) w.F64(d);
}

Status ReadIntrinsics(ByteReader& r, const char* field, const Limits& limits, Intrinsics* in) {
  uint32_t width = 0, height = 0;
  HOLO_RETURN_IF_ERROR(r.U32(field, &width));
  HOLO_RETURN_IF_ERROR(r.U32(field, &height));
  if (width == 0 || height == 0 || width > limits.max_image_dim || height > limits.max_image_dim) {
    return DataLoss(std::string(field) + ": image size " + Str(width) + "x" + Str(height) + " outside 1.." +
                    Str(limits.max_image_dim));
  }
  in->width = static_cast<int>(width);
  in->height = static_cast<int>(height);
  HOLO_RETURN_IF_ERROR(r.F64(field, &in->fx));
  HOLO_RETURN_IF_ERROR(r.F64(field, &in->fy));
  HOLO_RETURN_IF_ERROR(r.F64(field, &in->cx));
  HOLO_RETURN_IF_ERROR(r.F64(field, &in->cy));
  for (double& d : in->distortion) HOLO_RETURN_IF_ERROR(r.F64(field, &d));
  if (!(in->fx > 0) || !(in->fy > 0)) return DataLoss(std::string(field) + ": focal length must be > 0");
  return OkStatus();
}

template <size_t N>
void WriteFloats(ByteWriter& w, const std::array<float, N>& a) {
  for (float f : a) w.F32(f);
}
template <size_t N>
Status ReadFloats(ByteReader& r, const char* field, std::array<float, N>* a) {
  for (float& f : *a) HOLO_RETURN_IF_ERROR(r.F32(field, &f));
  return OkStatus();
}

Status CheckQuaternion(const char* field, const std::array<float, 4>& q) {
  const float n = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3];
  if (std::abs(n - 1.0f) > 1e-3f) return DataLoss(std::string(field) + ": quaternion is not unit length");
  return OkStatus();
}

Status CheckFov(const char* field, const std::array<float, 4>& f) {
  for (float t : f) {
    if (!(t > 0.0f) || t > 100.0f) return DataLoss(std::string(field) + ": FOV tangents must be in (0, 100]");
  }
  return OkStatus();
}

void WriteBytes32(ByteWriter& w, const std::vector<uint8_t>& b) { w.Blob32(b); }
Status ReadBytes32(ByteReader& r, const char* field, size_t max_len, std::vector<uint8_t>* b) {
  std::span<const uint8_t> v;
  HOLO_RETURN_IF_ERROR(r.Blob32(field, max_len, &v));
  b->assign(v.begin(), v.end());
  return OkStatus();
}

// ---------------------------------------------------------------- per type

void Write(ByteWriter& w, const Hello& m) {
  w.U8(static_cast<uint8_t>(m.role));
  w.U16(m.min_version);
  w.U16(m.max_version);
  WriteCodecList(w, m.capabilities.geometry);
  WriteCodecList(w, m.capabilities.color);
  WriteCodecList(w, m.capabilities.audio);
  w.String16(m.access_token);
  w.String16(m.client_name);
}
Status Read(ByteReader& r, const Limits& l, Hello* m) {
  uint8_t role = 0;
  HOLO_RETURN_IF_ERROR(r.U8("hello.role", &role));
  if (role < 1 || role > 6) return DataLoss("hello.role: unknown role " + Str(role));
  m->role = static_cast<Role>(role);
  HOLO_RETURN_IF_ERROR(r.U16("hello.min_version", &m->min_version));
  HOLO_RETURN_IF_ERROR(r.U16("hello.max_version", &m->max_version));
  if (m->min_version > m->max_version) return DataLoss("hello.min_version: greater than max_version");
  HOLO_RETURN_IF_ERROR(ReadCodecList(r, "hello.geometry_codecs", 4, &m->capabilities.geometry));
  HOLO_RETURN_IF_ERROR(ReadCodecList(r, "hello.color_codecs", 4, &m->capabilities.color));
  HOLO_RETURN_IF_ERROR(ReadCodecList(r, "hello.audio_codecs", kMaxAudioCodec, &m->capabilities.audio));
  HOLO_RETURN_IF_ERROR(r.String16("hello.access_token", l.max_token, &m->access_token));
  HOLO_RETURN_IF_ERROR(r.String16("hello.client_name", l.max_string, &m->client_name));
  return OkStatus();
}

void Write(ByteWriter& w, const Welcome& m) {
  w.U64(m.session_id);
  w.U16(m.version);
  w.U8(static_cast<uint8_t>(m.geometry_codec));
  w.U8(static_cast<uint8_t>(m.color_codec));
  w.U8(static_cast<uint8_t>(m.audio_codec));
  w.U32(m.max_message_bytes);
  w.String16(m.server_name);
}
Status Read(ByteReader& r, const Limits& l, Welcome* m) {
  HOLO_RETURN_IF_ERROR(r.U64("welcome.session_id", &m->session_id));
  HOLO_RETURN_IF_ERROR(r.U16("welcome.version", &m->version));
  uint8_t g = 0, c = 0, a = 0;
  HOLO_RETURN_IF_ERROR(r.U8("welcome.geometry_codec", &g));
  HOLO_RETURN_IF_ERROR(r.U8("welcome.color_codec", &c));
  HOLO_RETURN_IF_ERROR(r.U8("welcome.audio_codec", &a));
  if (g < 1 || g > 4 || g == 3) return DataLoss("welcome.geometry_codec: unknown codec " + Str(g));
  if (c < 1 || c > 4) return DataLoss("welcome.color_codec: unknown codec " + Str(c));
  if (a < 1 || a > kMaxAudioCodec) return DataLoss("welcome.audio_codec: unknown codec " + Str(a));
  m->geometry_codec = static_cast<GeometryCodec>(g);
  m->color_codec = static_cast<ColorCodec>(c);
  m->audio_codec = static_cast<AudioCodec>(a);
  HOLO_RETURN_IF_ERROR(r.U32("welcome.max_message_bytes", &m->max_message_bytes));
  HOLO_RETURN_IF_ERROR(r.String16("welcome.server_name", l.max_string, &m->server_name));
  return OkStatus();
}

void Write(ByteWriter& w, const Refuse& m) {
  w.U16(static_cast<uint16_t>(m.reason));
  w.U16(m.server_min_version);
  w.U16(m.server_max_version);
  w.String16(m.message);
}
Status Read(ByteReader& r, const Limits& l, Refuse* m) {
  uint16_t reason = 0;
  HOLO_RETURN_IF_ERROR(r.U16("refuse.reason", &reason));
  if (reason < 1 || reason > 7) return DataLoss("refuse.reason: unknown reason " + Str(reason));
  m->reason = static_cast<RefuseReason>(reason);
  HOLO_RETURN_IF_ERROR(r.U16("refuse.server_min_version", &m->server_min_version));
  HOLO_RETURN_IF_ERROR(r.U16("refuse.server_max_version", &m->server_max_version));
  HOLO_RETURN_IF_ERROR(r.String16("refuse.message", l.max_string, &m->message));
  return OkStatus();
}

// Smallest encoded pod: id + 2 empty strings' lengths... used for the count check.
constexpr size_t kMinPodBytes = 4 + 2 + 2 * (8 + 9 * 8) + 2 * 48;

void Write(ByteWriter& w, const RigMessage& m) {
  w.String16(m.rig.name);
  HOLO_CHECK(m.rig.pods.size() <= 0xFFFF);
  w.U16(static_cast<uint16_t>(m.rig.pods.size()));
  for (const PodCalibration& p : m.rig.pods) {
    w.I32(p.id);
    w.String16(p.name);
    WriteIntrinsics(w, p.depth);
    WriteIntrinsics(w, p.color);
    WritePose(w, p.color_from_depth);
    WritePose(w, p.world_from_depth);
  }
}
Status Read(ByteReader& r, const Limits& l, RigMessage* m) {
  HOLO_RETURN_IF_ERROR(r.String16("rig.name", l.max_string, &m->rig.name));
  uint16_t n = 0;
  HOLO_RETURN_IF_ERROR(r.U16("rig.num_pods", &n));
  if (n > l.max_pods) return DataLoss("rig.num_pods: " + Str(n) + " exceeds limit " + Str(l.max_pods));
  HOLO_RETURN_IF_ERROR(r.CheckCount("rig.num_pods", n, kMinPodBytes));
  m->rig.pods.resize(n);
  for (PodCalibration& p : m->rig.pods) {
    HOLO_RETURN_IF_ERROR(r.I32("rig.pod.id", &p.id));
    HOLO_RETURN_IF_ERROR(r.String16("rig.pod.name", l.max_string, &p.name));
    HOLO_RETURN_IF_ERROR(ReadIntrinsics(r, "rig.pod.depth", l, &p.depth));
    HOLO_RETURN_IF_ERROR(ReadIntrinsics(r, "rig.pod.color", l, &p.color));
    HOLO_RETURN_IF_ERROR(ReadPose(r, "rig.pod.color_from_depth", &p.color_from_depth));
    HOLO_RETURN_IF_ERROR(ReadPose(r, "rig.pod.world_from_depth", &p.world_from_depth));
  }
  return OkStatus();
}

void Write(ByteWriter& w, const MeshFrame& m) {
  w.I64(m.frame_index);
  w.U8(static_cast<uint8_t>(m.codec));
  WriteBytes32(w, m.data);
}
Status Read(ByteReader& r, const Limits& l, MeshFrame* m) {
  HOLO_RETURN_IF_ERROR(r.I64("mesh_frame.frame_index", &m->frame_index));
  uint8_t c = 0;
  HOLO_RETURN_IF_ERROR(r.U8("mesh_frame.codec", &c));
  if (c < 1 || c > 4 || c == 3) return DataLoss("mesh_frame.codec: unknown geometry codec " + Str(c));
  m->codec = static_cast<GeometryCodec>(c);
  return ReadBytes32(r, "mesh_frame.data", l.max_message_bytes, &m->data);
}

void Write(ByteWriter& w, const ColorFrame& m) {
  w.I64(m.frame_index);
  w.U8(static_cast<uint8_t>(m.codec));
  HOLO_CHECK(m.images.size() <= 0xFF);
  w.U8(static_cast<uint8_t>(m.images.size()));
  for (const PodImage& im : m.images) {
    w.U16(im.pod_id);
    WriteBytes32(w, im.data);
  }
}
Status Read(ByteReader& r, const Limits& l, ColorFrame* m) {
  HOLO_RETURN_IF_ERROR(r.I64("color_frame.frame_index", &m->frame_index));
  uint8_t c = 0, n = 0;
  HOLO_RETURN_IF_ERROR(r.U8("color_frame.codec", &c));
  if (c < 1 || c > 4) return DataLoss("color_frame.codec: unknown color codec " + Str(c));
  m->codec = static_cast<ColorCodec>(c);
  HOLO_RETURN_IF_ERROR(r.U8("color_frame.num_images", &n));
  if (n > l.max_pods) return DataLoss("color_frame.num_images: " + Str(n) + " exceeds limit " + Str(l.max_pods));
  HOLO_RETURN_IF_ERROR(r.CheckCount("color_frame.num_images", n, 6));
  m->images.resize(n);
  for (PodImage& im : m->images) {
    HOLO_RETURN_IF_ERROR(r.U16("color_frame.pod_id", &im.pod_id));
    HOLO_RETURN_IF_ERROR(ReadBytes32(r, "color_frame.image", l.max_message_bytes, &im.data));
  }
  return OkStatus();
}

// ---- lean AudioPose (codec 3, PROTOCOL.md §9.1)

constexpr uint8_t kLeanHasPose = 1u << 0;
constexpr uint8_t kLeanWidePosition = 1u << 1;
constexpr uint8_t kLeanKnownFlags = kLeanHasPose | kLeanWidePosition;
constexpr double kLeanAngleStep = 2.0 * 3.14159265358979323846 / 65536.0;  // rad
constexpr int32_t kLeanMaxMm = 1000000;  // ±1 km: the audio path refuses heads farther out

int32_t PositionMm(float v) {
  if (!std::isfinite(v)) return 0;
  const double mm = std::clamp(static_cast<double>(v) * 1000.0, -double{kLeanMaxMm}, double{kLeanMaxMm});
  return static_cast<int32_t>(std::lrint(mm));
}

int16_t AngleSteps(float v) {
  if (!std::isfinite(v)) return 0;
  // remainder() puts the angle in [−π, π]; +π and −π are the same rotation.
  const double a = std::remainder(static_cast<double>(v), 2.0 * 3.14159265358979323846);
  long q = std::lrint(a / kLeanAngleStep);
  if (q >= 32768) q -= 65536;
  if (q < -32768) q += 65536;
  return static_cast<int16_t>(q);
}

struct LeanPose {
  std::array<int32_t, 3> mm{};
  std::array<int16_t, 3> angle{};
  bool wide = false;
};

LeanPose ToLean(const HeadPose& p) {
  LeanPose q;
  q.mm = {PositionMm(p.x), PositionMm(p.y), PositionMm(p.z)};
  q.angle = {AngleSteps(p.yaw), AngleSteps(p.pitch), AngleSteps(p.roll)};
  for (int32_t v : q.mm) q.wide = q.wide || v > 32767 || v < -32768;
  return q;
}

HeadPose FromLean(const LeanPose& q) {
  HeadPose p;
  p.x = static_cast<float>(q.mm[0] * 1e-3);
  p.y = static_cast<float>(q.mm[1] * 1e-3);
  p.z = static_cast<float>(q.mm[2] * 1e-3);
  p.yaw = static_cast<float>(q.angle[0] * kLeanAngleStep);
  p.pitch = static_cast<float>(q.angle[1] * kLeanAngleStep);
  p.roll = static_cast<float>(q.angle[2] * kLeanAngleStep);
  return p;
}

void WriteLean(ByteWriter& w, const AudioPose& m) {
  const LeanPose q = ToLean(m.pose);
  uint8_t flags = 0;
  if (m.has_pose) flags |= kLeanHasPose;
  if (m.has_pose && q.wide) flags |= kLeanWidePosition;
  w.U8(static_cast<uint8_t>(AudioCodec::kOpusLean));
  w.U8(flags);
  if (m.has_pose) {
    for (int32_t v : q.mm) {
      if (q.wide) {
        w.I32(v);
      } else {
        w.U16(static_cast<uint16_t>(static_cast<int16_t>(v)));
      }
    }
    for (int16_t a : q.angle) w.U16(static_cast<uint16_t>(a));
  }
  HOLO_CHECK(m.audio.size() <= 0xFFFF);
  w.Bytes(m.audio);
}

Status ReadLean(ByteReader& r, AudioPose* m) {
  m->codec = AudioCodec::kOpusLean;
  m->channels = 1;
  m->sample_rate = 48000;
  m->duration_us_div10 = 2000;
  m->sequence = 0;
  m->capture_time_us = 0;
  uint8_t flags = 0;
  HOLO_RETURN_IF_ERROR(r.U8("audio_pose.lean_flags", &flags));
  if (flags & ~kLeanKnownFlags) return DataLoss("audio_pose.lean_flags: unknown flag bits set");
  m->has_pose = (flags & kLeanHasPose) != 0;
  if (!m->has_pose && (flags & kLeanWidePosition)) {
    return DataLoss("audio_pose.lean_flags: wide position without a pose");
  }
  m->pose = {};
  if (m->has_pose) {
    LeanPose q;
    q.wide = (flags & kLeanWidePosition) != 0;
    for (int32_t& v : q.mm) {
      if (q.wide) {
        HOLO_RETURN_IF_ERROR(r.I32("audio_pose.lean_position", &v));
        if (v > kLeanMaxMm || v < -kLeanMaxMm) return DataLoss("audio_pose.lean_position: beyond ±1 km");
      } else {
        uint16_t u = 0;
        HOLO_RETURN_IF_ERROR(r.U16("audio_pose.lean_position", &u));
        v = static_cast<int16_t>(u);
      }
    }
    for (int16_t& a : q.angle) {
      uint16_t u = 0;
      HOLO_RETURN_IF_ERROR(r.U16("audio_pose.lean_angle", &u));
      a = static_cast<int16_t>(u);
    }
    m->pose = FromLean(q);
  }
  // The Opus packet is the rest of the payload: RFC 6716 allows 1..1275 bytes.
  const size_t n = r.remaining();
  if (n == 0) return DataLoss("audio_pose.audio: lean frame without an Opus packet");
  if (n > 1275) return DataLoss("audio_pose.audio: lean frame's Opus packet of " + Str(n) + " bytes exceeds 1275");
  std::span<const uint8_t> b;
  HOLO_RETURN_IF_ERROR(r.View("audio_pose.audio", n, &b));
  m->audio.assign(b.begin(), b.end());
  return OkStatus();
}

void Write(ByteWriter& w, const AudioPose& m) {
  if (m.codec == AudioCodec::kOpusLean) return WriteLean(w, m);
  w.U8(static_cast<uint8_t>(m.codec));
  w.U8(m.channels);
  w.U16(m.duration_us_div10);
  w.U32(m.sample_rate);
  w.U32(m.sequence);
  w.I64(m.capture_time_us);
  for (float f : {m.pose.x, m.pose.y, m.pose.z, m.pose.yaw, m.pose.pitch, m.pose.roll}) w.F32(f);
  HOLO_CHECK(m.audio.size() <= 0xFFFF);
  w.U16(static_cast<uint16_t>(m.audio.size()));
  w.Bytes(m.audio);
}
Status Read(ByteReader& r, const Limits&, AudioPose* m) {
  uint8_t c = 0;
  HOLO_RETURN_IF_ERROR(r.U8("audio_pose.codec", &c));
  if (c < 1 || c > kMaxAudioCodec) return DataLoss("audio_pose.codec: unknown audio codec " + Str(c));
  if (c == static_cast<uint8_t>(AudioCodec::kOpusLean)) return ReadLean(r, m);
  m->codec = static_cast<AudioCodec>(c);
  m->has_pose = true;
  HOLO_RETURN_IF_ERROR(r.U8("audio_pose.channels", &m->channels));
  if (m->channels < 1 || m->channels > 2) return DataLoss("audio_pose.channels: must be 1 or 2, got " + Str(m->channels));
  HOLO_RETURN_IF_ERROR(r.U16("audio_pose.duration", &m->duration_us_div10));
  if (m->duration_us_div10 == 0) return DataLoss("audio_pose.duration: must be > 0");
  HOLO_RETURN_IF_ERROR(r.U32("audio_pose.sample_rate", &m->sample_rate));
  if (m->sample_rate < 8000 || m->sample_rate > 192000) {
    return DataLoss("audio_pose.sample_rate: " + Str(m->sample_rate) + " outside 8000..192000");
  }
  HOLO_RETURN_IF_ERROR(r.U32("audio_pose.sequence", &m->sequence));
  HOLO_RETURN_IF_ERROR(r.I64("audio_pose.capture_time_us", &m->capture_time_us));
  for (float* f : {&m->pose.x, &m->pose.y, &m->pose.z, &m->pose.yaw, &m->pose.pitch, &m->pose.roll}) {
    HOLO_RETURN_IF_ERROR(r.F32("audio_pose.pose", f));
  }
  uint16_t n = 0;
  HOLO_RETURN_IF_ERROR(r.U16("audio_pose.audio_bytes", &n));
  std::span<const uint8_t> b;
  HOLO_RETURN_IF_ERROR(r.View("audio_pose.audio", n, &b));
  if (m->codec == AudioCodec::kPcm16) {
    // PCM must hold exactly duration × rate × channels samples of 2 bytes.
    const uint64_t samples = uint64_t{m->duration_us_div10} * m->sample_rate / 100000 * m->channels;
    if (uint64_t{n} != samples * 2) {
      return DataLoss("audio_pose.audio: PCM frame has " + Str(n) + " bytes, expected " + Str(samples * 2));
    }
  }
  m->audio.assign(b.begin(), b.end());
  return OkStatus();
}

void Write(ByteWriter& w, const ClientPose& m) {
  w.I64(m.time_us);
  w.I64(m.predicted_display_us);
  WriteFloats(w, m.position);
  WriteFloats(w, m.rotation);
  WriteFloats(w, m.fov_tan);
}
Status Read(ByteReader& r, const Limits&, ClientPose* m) {
  HOLO_RETURN_IF_ERROR(r.I64("client_pose.time_us", &m->time_us));
  HOLO_RETURN_IF_ERROR(r.I64("client_pose.predicted_display_us", &m->predicted_display_us));
  HOLO_RETURN_IF_ERROR(ReadFloats(r, "client_pose.position", &m->position));
  HOLO_RETURN_IF_ERROR(ReadFloats(r, "client_pose.rotation", &m->rotation));
  HOLO_RETURN_IF_ERROR(CheckQuaternion("client_pose.rotation", m->rotation));
  HOLO_RETURN_IF_ERROR(ReadFloats(r, "client_pose.fov_tan", &m->fov_tan));
  return CheckFov("client_pose.fov_tan", m->fov_tan);
}

void Write(ByteWriter& w, const RenderedFrame& m) {
  w.I64(m.frame_index);
  w.I64(m.pose_time_us);
  WriteFloats(w, m.position);
  WriteFloats(w, m.rotation);
  WriteFloats(w, m.fov_tan);
  w.U16(m.width);
  w.U16(m.height);
  w.U8(static_cast<uint8_t>(m.codec));
  WriteBytes32(w, m.image);
  WriteBytes32(w, m.depth);
}
Status Read(ByteReader& r, const Limits& l, RenderedFrame* m) {
  HOLO_RETURN_IF_ERROR(r.I64("rendered_frame.frame_index", &m->frame_index));
  HOLO_RETURN_IF_ERROR(r.I64("rendered_frame.pose_time_us", &m->pose_time_us));
  HOLO_RETURN_IF_ERROR(ReadFloats(r, "rendered_frame.position", &m->position));
  HOLO_RETURN_IF_ERROR(ReadFloats(r, "rendered_frame.rotation", &m->rotation));
  HOLO_RETURN_IF_ERROR(CheckQuaternion("rendered_frame.rotation", m->rotation));
  HOLO_RETURN_IF_ERROR(ReadFloats(r, "rendered_frame.fov_tan", &m->fov_tan));
  HOLO_RETURN_IF_ERROR(CheckFov("rendered_frame.fov_tan", m->fov_tan));
  HOLO_RETURN_IF_ERROR(r.U16("rendered_frame.width", &m->width));
  HOLO_RETURN_IF_ERROR(r.U16("rendered_frame.height", &m->height));
  if (m->width == 0 || m->height == 0 || m->width > l.max_image_dim || m->height > l.max_image_dim) {
    return DataLoss("rendered_frame.width: image size " + Str(m->width) + "x" + Str(m->height) + " outside 1.." +
                    Str(l.max_image_dim));
  }
  uint8_t c = 0;
  HOLO_RETURN_IF_ERROR(r.U8("rendered_frame.codec", &c));
  if (c < 1 || c > 3) return DataLoss("rendered_frame.codec: unknown color codec " + Str(c));
  m->codec = static_cast<ColorCodec>(c);
  HOLO_RETURN_IF_ERROR(ReadBytes32(r, "rendered_frame.image", l.max_message_bytes, &m->image));
  return ReadBytes32(r, "rendered_frame.depth", l.max_message_bytes, &m->depth);
}

void Write(ByteWriter& w, const Control& m) {
  w.U8(static_cast<uint8_t>(m.command));
  w.U32(m.stream_id);
  w.I64(m.value);
  w.F32(m.speed);
}
Status Read(ByteReader& r, const Limits&, Control* m) {
  uint8_t c = 0;
  HOLO_RETURN_IF_ERROR(r.U8("control.command", &c));
  if (c < 1 || c > 9) return DataLoss("control.command: unknown command " + Str(c));
  m->command = static_cast<ControlCommand>(c);
  HOLO_RETURN_IF_ERROR(r.U32("control.stream_id", &m->stream_id));
  HOLO_RETURN_IF_ERROR(r.I64("control.value", &m->value));
  HOLO_RETURN_IF_ERROR(r.F32("control.speed", &m->speed));
  if (m->command == ControlCommand::kSetSpeed && (m->speed < 0.1f || m->speed > 8.0f)) {
    return DataLoss("control.speed: must be in [0.1, 8]");
  }
  if (m->command == ControlCommand::kSetLoop && m->value != 0 && m->value != 1) {
    return DataLoss("control.value: set loop takes 0 or 1, got " + std::to_string(m->value));
  }
  if (m->command == ControlCommand::kSetQuality && (m->value < 0 || m->value > 10)) {
    return DataLoss("control.value: quality level must be in [0, 10], got " + std::to_string(m->value));
  }
  return OkStatus();
}

void Write(ByteWriter& w, const Ping& m) {
  w.U64(m.nonce);
  w.I64(m.send_time_us);
}
Status Read(ByteReader& r, const Limits&, Ping* m) {
  HOLO_RETURN_IF_ERROR(r.U64("ping.nonce", &m->nonce));
  return r.I64("ping.send_time_us", &m->send_time_us);
}

void Write(ByteWriter& w, const Pong& m) {
  w.U64(m.nonce);
  w.I64(m.ping_send_time_us);
  w.I64(m.receive_time_us);
  w.I64(m.send_time_us);
}
Status Read(ByteReader& r, const Limits&, Pong* m) {
  HOLO_RETURN_IF_ERROR(r.U64("pong.nonce", &m->nonce));
  HOLO_RETURN_IF_ERROR(r.I64("pong.ping_send_time_us", &m->ping_send_time_us));
  HOLO_RETURN_IF_ERROR(r.I64("pong.receive_time_us", &m->receive_time_us));
  return r.I64("pong.send_time_us", &m->send_time_us);
}

void Write(ByteWriter& w, const Stats& m) {
  HOLO_CHECK(m.values.size() <= 0xFFFF);
  w.U16(static_cast<uint16_t>(m.values.size()));
  for (const auto& [k, v] : m.values) {
    w.String8(k);
    w.F64(v);
  }
}
Status Read(ByteReader& r, const Limits& l, Stats* m) {
  uint16_t n = 0;
  HOLO_RETURN_IF_ERROR(r.U16("stats.count", &n));
  if (n > l.max_stats) return DataLoss("stats.count: " + Str(n) + " exceeds limit " + Str(l.max_stats));
  HOLO_RETURN_IF_ERROR(r.CheckCount("stats.count", n, 1 + 8));
  m->values.resize(n);
  for (auto& [k, v] : m->values) {
    HOLO_RETURN_IF_ERROR(r.String8("stats.key", &k));
    HOLO_RETURN_IF_ERROR(r.F64("stats.value", &v));
  }
  return OkStatus();
}

void Write(ByteWriter& w, const PodFrame& m) {
  w.U16(m.pod_id);
  w.I64(m.frame_number);
  w.I64(m.capture_time_us);
  w.U8(static_cast<uint8_t>(m.depth_codec));
  WriteBytes32(w, m.depth);
  w.U8(static_cast<uint8_t>(m.color_codec));
  WriteBytes32(w, m.color);
}
Status Read(ByteReader& r, const Limits& l, PodFrame* m) {
  HOLO_RETURN_IF_ERROR(r.U16("pod_frame.pod_id", &m->pod_id));
  HOLO_RETURN_IF_ERROR(r.I64("pod_frame.frame_number", &m->frame_number));
  if (m->frame_number < 0) return DataLoss("pod_frame.frame_number: must be >= 0, got " + std::to_string(m->frame_number));
  HOLO_RETURN_IF_ERROR(r.I64("pod_frame.capture_time_us", &m->capture_time_us));
  uint8_t d = 0, c = 0;
  HOLO_RETURN_IF_ERROR(r.U8("pod_frame.depth_codec", &d));
  if (d < 1 || d > 2) return DataLoss("pod_frame.depth_codec: unknown depth codec " + Str(d));
  m->depth_codec = static_cast<DepthCodec>(d);
  HOLO_RETURN_IF_ERROR(ReadBytes32(r, "pod_frame.depth", l.max_message_bytes, &m->depth));
  if (m->depth.empty()) return DataLoss("pod_frame.depth: empty");
  HOLO_RETURN_IF_ERROR(r.U8("pod_frame.color_codec", &c));
  if (c < 1 || c > 2) return DataLoss("pod_frame.color_codec: unknown or unsupported colour codec " + Str(c));
  m->color_codec = static_cast<ColorCodec>(c);
  HOLO_RETURN_IF_ERROR(ReadBytes32(r, "pod_frame.color", l.max_message_bytes, &m->color));
  if (m->color.empty()) return DataLoss("pod_frame.color: empty");
  return OkStatus();
}

void Write(ByteWriter& w, const Regions& m) {
  HOLO_CHECK(m.regions.size() <= kMaxRegions);
  w.I64(m.frame_index);
  w.U8(static_cast<uint8_t>(m.regions.size()));
  for (const RegionReport& r : m.regions) {
    HOLO_CHECK(!r.name.empty() && r.name.size() <= kMaxRegionName);
    w.String8(r.name);
    w.U8(static_cast<uint8_t>(r.shape));
    WriteFloats(w, r.a);
    if (r.shape == RegionShape::kBox) {
      WriteFloats(w, r.b);
    } else {
      w.F32(r.b[0]);
    }
    w.U8(static_cast<uint8_t>(r.state));
    w.F32(r.occupied_litres);
  }
}
Status Read(ByteReader& r, const Limits&, Regions* m) {
  HOLO_RETURN_IF_ERROR(r.I64("regions.frame_index", &m->frame_index));
  if (m->frame_index < 0) return DataLoss("regions.frame_index: must be >= 0, got " + std::to_string(m->frame_index));
  uint8_t n = 0;
  HOLO_RETURN_IF_ERROR(r.U8("regions.count", &n));
  if (n > kMaxRegions) return DataLoss("regions.count: " + Str(n) + " exceeds limit " + Str(kMaxRegions));
  // Smallest region: 1-byte name (2) + shape (1) + sphere (16) + state (1) + volume (4).
  HOLO_RETURN_IF_ERROR(r.CheckCount("regions.count", n, 24));
  m->regions.resize(n);
  for (size_t i = 0; i < n; ++i) {
    RegionReport& g = m->regions[i];
    HOLO_RETURN_IF_ERROR(r.String8("regions.name", &g.name));
    if (g.name.empty() || g.name.size() > kMaxRegionName)
      return DataLoss("regions.name: " + Str(g.name.size()) + " bytes, must be 1.." + Str(kMaxRegionName));
    for (size_t j = 0; j < i; ++j)
      if (m->regions[j].name == g.name) return DataLoss("regions.name: '" + g.name + "' appears twice");
    uint8_t shape = 0;
    HOLO_RETURN_IF_ERROR(r.U8("regions.shape", &shape));
    if (shape != 1 && shape != 2) return DataLoss("regions.shape: unknown shape " + Str(shape));
    g.shape = static_cast<RegionShape>(shape);
    HOLO_RETURN_IF_ERROR(ReadFloats(r, "regions.a", &g.a));
    if (g.shape == RegionShape::kBox) {
      HOLO_RETURN_IF_ERROR(ReadFloats(r, "regions.b", &g.b));
      for (int k = 0; k < 3; ++k)
        if (!(g.a[k] < g.b[k])) return DataLoss("regions.b: box max must exceed min on every axis");
    } else {
      g.b = {0, 0, 0};
      HOLO_RETURN_IF_ERROR(r.F32("regions.radius", &g.b[0]));
      if (!(g.b[0] > 0)) return DataLoss("regions.radius: must be > 0");
    }
    uint8_t state = 0;
    HOLO_RETURN_IF_ERROR(r.U8("regions.state", &state));
    if (state > 3) return DataLoss("regions.state: unknown state " + Str(state));
    g.state = static_cast<RegionState>(state);
    HOLO_RETURN_IF_ERROR(r.F32("regions.occupied_litres", &g.occupied_litres));
    if (g.occupied_litres < 0) return DataLoss("regions.occupied_litres: must be >= 0");
  }
  return OkStatus();
}

template <typename T>
StatusOr<Payload> ReadAs(ByteReader& r, const Limits& l, const char* name) {
  T m;
  HOLO_RETURN_IF_ERROR(Read(r, l, &m));
  HOLO_RETURN_IF_ERROR(r.ExpectEnd(name));
  return Payload(std::move(m));
}

}  // namespace

// ---------------------------------------------------------------- public

Status Limits::Check() const {
  const Limits hard;
  if (max_frame_payload == 0 || max_frame_payload > hard.max_frame_payload) {
    return InvalidArgument("max_frame_payload must be in 1.." + Str(hard.max_frame_payload));
  }
  if (max_message_bytes == 0 || max_message_bytes > hard.max_message_bytes) {
    return InvalidArgument("max_message_bytes must be in 1.." + Str(hard.max_message_bytes));
  }
  if (max_vertices > hard.max_vertices || max_triangles > hard.max_triangles || max_pods > hard.max_pods ||
      max_image_dim > hard.max_image_dim || max_image_pixels > hard.max_image_pixels || max_string > hard.max_string || max_token > hard.max_token ||
      max_stats > hard.max_stats) {
    return InvalidArgument("limits may be lowered, not raised above the protocol's hard limits");
  }
  return OkStatus();
}

const char* MessageTypeName(MessageType t) {
  switch (t) {
    case MessageType::kHello: return "hello";
    case MessageType::kWelcome: return "welcome";
    case MessageType::kRefuse: return "refuse";
    case MessageType::kRig: return "rig";
    case MessageType::kMeshFrame: return "mesh_frame";
    case MessageType::kColorFrame: return "color_frame";
    case MessageType::kAudioPose: return "audio_pose";
    case MessageType::kClientPose: return "client_pose";
    case MessageType::kRenderedFrame: return "rendered_frame";
    case MessageType::kControl: return "control";
    case MessageType::kPing: return "ping";
    case MessageType::kPong: return "pong";
    case MessageType::kStats: return "stats";
    case MessageType::kPodFrame: return "pod_frame";
    case MessageType::kRegions: return "regions";
  }
  return "unknown";
}

bool IsKnownMessageType(uint16_t t) { return t >= 1 && t <= 15; }

const char* RegionStateName(RegionState s) {
  switch (s) {
    case RegionState::kEmpty: return "empty";
    case RegionState::kEnter: return "enter";
    case RegionState::kStay: return "stay";
    case RegionState::kLeave: return "leave";
  }
  return "unknown";
}

const char* RoleName(Role r) {
  switch (r) {
    case Role::kPublisher: return "publisher";
    case Role::kViewer: return "viewer";
    case Role::kRenderHost: return "render-host";
    case Role::kThinClient: return "thin-client";
    case Role::kRecorder: return "recorder";
    case Role::kPod: return "pod";
  }
  return "unknown";
}

void EncodeHeader(const Header& h, uint8_t out[kHeaderSize]) {
  std::vector<uint8_t> buf;
  buf.reserve(kHeaderSize);
  ByteWriter w(&buf);
  w.U32(kMagic);
  w.U16(h.version);
  w.U16(static_cast<uint16_t>(h.type));
  w.U16(h.flags);
  w.U16(0);  // reserved
  w.U32(h.stream_id);
  w.U32(h.sequence);
  w.I64(h.capture_time_us);
  w.U32(h.payload_length);
  HOLO_CHECK(buf.size() == kHeaderSize);
  std::memcpy(out, buf.data(), kHeaderSize);
}

StatusOr<Header> DecodeHeader(const uint8_t* data, size_t size, const Limits& limits) {
  ByteReader r(data, size);
  uint32_t magic = 0;
  HOLO_RETURN_IF_ERROR(r.U32("header.magic", &magic));
  if (magic != kMagic) return DataLoss("header.magic: not a Holoport stream (bad magic)");
  Header h;
  HOLO_RETURN_IF_ERROR(r.U16("header.version", &h.version));
  if (h.version != kProtocolVersion) {
    return UnsupportedVersion("header.version: peer speaks protocol version " + Str(h.version) +
                              ", this build speaks " + Str(kProtocolVersion));
  }
  uint16_t type = 0, reserved = 0;
  HOLO_RETURN_IF_ERROR(r.U16("header.type", &type));
  if (!IsKnownMessageType(type)) return DataLoss("header.type: unknown message type " + Str(type));
  h.type = static_cast<MessageType>(type);
  HOLO_RETURN_IF_ERROR(r.U16("header.flags", &h.flags));
  if (h.flags & ~kKnownFlags) return DataLoss("header.flags: unknown flag bits set");
  HOLO_RETURN_IF_ERROR(r.U16("header.reserved", &reserved));
  if (reserved != 0) return DataLoss("header.reserved: must be zero");
  HOLO_RETURN_IF_ERROR(r.U32("header.stream_id", &h.stream_id));
  HOLO_RETURN_IF_ERROR(r.U32("header.sequence", &h.sequence));
  HOLO_RETURN_IF_ERROR(r.I64("header.capture_time_us", &h.capture_time_us));
  HOLO_RETURN_IF_ERROR(r.U32("header.payload_length", &h.payload_length));
  if (h.payload_length > limits.max_frame_payload) {
    return DataLoss("header.payload_length: " + Str(h.payload_length) + " exceeds limit " +
                    Str(limits.max_frame_payload));
  }
  return h;
}

MessageType TypeOf(const Payload& p) {
  static constexpr MessageType kTypes[] = {
      MessageType::kHello,      MessageType::kWelcome,   MessageType::kRefuse,        MessageType::kRig,
      MessageType::kMeshFrame,  MessageType::kColorFrame, MessageType::kAudioPose,    MessageType::kClientPose,
      MessageType::kRenderedFrame, MessageType::kControl, MessageType::kPing,         MessageType::kPong,
      MessageType::kStats,      MessageType::kPodFrame,   MessageType::kRegions};
  return kTypes[p.index()];
}

HeadPose QuantizeLeanPose(const HeadPose& pose) { return FromLean(ToLean(pose)); }

HeadPose LerpPose(const HeadPose& a, const HeadPose& b, float t) {
  constexpr double kTwoPi = 2.0 * 3.14159265358979323846;
  auto angle = [&](float u, float v) {
    const double d = std::remainder(static_cast<double>(v) - static_cast<double>(u), kTwoPi);
    return static_cast<float>(std::remainder(static_cast<double>(u) + t * d, kTwoPi));
  };
  HeadPose m;
  m.x = a.x + t * (b.x - a.x);
  m.y = a.y + t * (b.y - a.y);
  m.z = a.z + t * (b.z - a.z);
  m.yaw = angle(a.yaw, b.yaw);
  m.pitch = angle(a.pitch, b.pitch);
  m.roll = angle(a.roll, b.roll);
  return m;
}

size_t LeanAudioPoseOverhead(const AudioPose& frame) {
  if (!frame.has_pose) return 2;
  return ToLean(frame.pose).wide ? 2 + 12 + 6 : 2 + 12;
}

AudioPose ToLeanAudioPose(AudioPose frame) {
  HOLO_CHECK(frame.codec == AudioCodec::kOpus || frame.codec == AudioCodec::kOpusLean);
  frame.codec = AudioCodec::kOpusLean;
  frame.channels = 1;
  frame.sample_rate = 48000;
  frame.duration_us_div10 = 2000;
  if (frame.has_pose) frame.pose = QuantizeLeanPose(frame.pose);
  else frame.pose = {};
  return frame;
}

AudioPose ToClassicAudioPose(AudioPose frame, const HeadPose& fallback_pose) {
  if (frame.codec != AudioCodec::kOpusLean) return frame;
  frame.codec = AudioCodec::kOpus;
  if (!frame.has_pose) frame.pose = fallback_pose;
  frame.has_pose = true;
  return frame;
}

void BindHeaderToPayload(const Payload& payload, Header* header) {
  header->type = TypeOf(payload);
  if (const auto* a = std::get_if<AudioPose>(&payload); a != nullptr && a->codec == AudioCodec::kOpusLean) {
    header->sequence = a->sequence;
    header->capture_time_us = a->capture_time_us;
  }
}

std::vector<uint8_t> EncodePayload(const Payload& payload) {
  std::vector<uint8_t> out;
  ByteWriter w(&out);
  std::visit([&](const auto& m) { Write(w, m); }, payload);
  return out;
}

StatusOr<Payload> DecodePayload(MessageType type, std::span<const uint8_t> bytes, const Limits& l) {
  ByteReader r(bytes);
  switch (type) {
    case MessageType::kHello: return ReadAs<Hello>(r, l, "hello");
    case MessageType::kWelcome: return ReadAs<Welcome>(r, l, "welcome");
    case MessageType::kRefuse: return ReadAs<Refuse>(r, l, "refuse");
    case MessageType::kRig: return ReadAs<RigMessage>(r, l, "rig");
    case MessageType::kMeshFrame: return ReadAs<MeshFrame>(r, l, "mesh_frame");
    case MessageType::kColorFrame: return ReadAs<ColorFrame>(r, l, "color_frame");
    case MessageType::kAudioPose: return ReadAs<AudioPose>(r, l, "audio_pose");
    case MessageType::kClientPose: return ReadAs<ClientPose>(r, l, "client_pose");
    case MessageType::kRenderedFrame: return ReadAs<RenderedFrame>(r, l, "rendered_frame");
    case MessageType::kControl: return ReadAs<Control>(r, l, "control");
    case MessageType::kPing: return ReadAs<Ping>(r, l, "ping");
    case MessageType::kPong: return ReadAs<Pong>(r, l, "pong");
    case MessageType::kStats: return ReadAs<Stats>(r, l, "stats");
    case MessageType::kPodFrame: return ReadAs<PodFrame>(r, l, "pod_frame");
    case MessageType::kRegions: return ReadAs<Regions>(r, l, "regions");
  }
  return DataLoss("unknown message type " + Str(static_cast<uint16_t>(type)));
}

StatusOr<Payload> DecodePayload(const Header& header, std::span<const uint8_t> bytes, const Limits& l) {
  HOLO_ASSIGN_OR_RETURN(Payload p, DecodePayload(header.type, bytes, l));
  if (auto* a = std::get_if<AudioPose>(&p); a != nullptr && a->codec == AudioCodec::kOpusLean) {
    a->sequence = header.sequence;
    a->capture_time_us = header.capture_time_us;
  }
  return p;
}

std::vector<uint8_t> EncodeMessage(Header header, const Payload& payload) {
  const std::vector<uint8_t> body = EncodePayload(payload);
  HOLO_CHECK(body.size() <= 0xFFFFFFFFull);
  BindHeaderToPayload(payload, &header);
  header.payload_length = static_cast<uint32_t>(body.size());
  std::vector<uint8_t> out(kHeaderSize);
  EncodeHeader(header, out.data());
  out.insert(out.end(), body.begin(), body.end());
  return out;
}

std::vector<std::vector<uint8_t>> EncodeFragmented(Header header, const Payload& payload, size_t fragment_bytes) {
  HOLO_CHECK(fragment_bytes > 0);
  const std::vector<uint8_t> body = EncodePayload(payload);
  BindHeaderToPayload(payload, &header);
  std::vector<std::vector<uint8_t>> frames;
  size_t off = 0;
  do {
    const size_t n = std::min(fragment_bytes, body.size() - off);
    Header h = header;
    h.payload_length = static_cast<uint32_t>(n);
    h.flags = static_cast<uint16_t>((header.flags & ~kFlagMoreFragments) |
                                    (off + n < body.size() ? kFlagMoreFragments : 0));
    std::vector<uint8_t> f(kHeaderSize);
    EncodeHeader(h, f.data());
    f.insert(f.end(), body.begin() + static_cast<ptrdiff_t>(off), body.begin() + static_cast<ptrdiff_t>(off + n));
    frames.push_back(std::move(f));
    off += n;
  } while (off < body.size());
  return frames;
}

StatusOr<Message> DecodeMessage(std::span<const uint8_t> bytes, const Limits& limits) {
  HOLO_ASSIGN_OR_RETURN(Header h, DecodeHeader(bytes.data(), bytes.size(), limits));
  if (h.flags & kFlagMoreFragments) return DataLoss("header.flags: a fragment is not a whole message");
  if (bytes.size() - kHeaderSize != h.payload_length) {
    return DataLoss("header.payload_length: says " + Str(h.payload_length) + " bytes, message has " +
                    Str(bytes.size() - kHeaderSize));
  }
  HOLO_ASSIGN_OR_RETURN(Payload p, DecodePayload(h, bytes.subspan(kHeaderSize), limits));
  return Message{h, std::move(p)};
}

Status FrameParser::Feed(const uint8_t* data, size_t size) {
  if (!status_.ok()) return status_;
  while (size > 0) {
    if (!have_header_) {
      const size_t n = std::min(size, kHeaderSize - header_fill_);
      std::memcpy(header_buf_ + header_fill_, data, n);
      header_fill_ += n;
      data += n;
      size -= n;
      if (header_fill_ < kHeaderSize) break;
      auto h = DecodeHeader(header_buf_, kHeaderSize, limits_);
      if (!h.ok()) {
        status_ = h.status();
        return status_;
      }
      header_ = *h;
      have_header_ = true;
      payload_.clear();
      payload_.reserve(header_.payload_length);  // bounded by limits_.max_frame_payload
    }
    const size_t want = header_.payload_length - payload_.size();
    const size_t n = std::min(size, want);
    payload_.insert(payload_.end(), data, data + n);
    data += n;
    size -= n;
    if (payload_.size() == header_.payload_length) {
      ready_.push_back(Frame{header_, std::move(payload_)});
      payload_ = {};
      have_header_ = false;
      header_fill_ = 0;
    }
  }
  return OkStatus();
}

bool FrameParser::Next(Frame* out) {
  if (ready_.empty()) return false;
  *out = std::move(ready_.front());
  ready_.pop_front();
  return true;
}

Status MessageAssembler::Add(Frame&& frame, bool* complete, Message* out) {
  *complete = false;
  const auto key = std::make_pair(frame.header.stream_id, static_cast<uint16_t>(frame.header.type));
  auto it = partial_.find(key);
  const bool more = frame.header.flags & kFlagMoreFragments;
  if (it == partial_.end() && !more) {
    HOLO_ASSIGN_OR_RETURN(Payload p, DecodePayload(frame.header, frame.payload, limits_));
    *out = Message{frame.header, std::move(p)};
    *complete = true;
    return OkStatus();
  }
  if (it == partial_.end()) {
    if (partial_.size() >= max_in_progress_) {
      return DataLoss("fragments: more than " + Str(max_in_progress_) + " messages in progress");
    }
    it = partial_.emplace(key, Partial{frame.header, {}}).first;
  } else if (it->second.first.sequence != frame.header.sequence ||
             it->second.first.capture_time_us != frame.header.capture_time_us) {
    return DataLoss("fragments: fragment of sequence " + Str(frame.header.sequence) +
                    " interrupts message of sequence " + Str(it->second.first.sequence) + " on stream " +
                    Str(frame.header.stream_id));
  }
  Partial& p = it->second;
  if (frame.payload.size() > limits_.max_message_bytes - p.bytes.size()) {
    partial_.erase(it);
    return DataLoss("fragments: reassembled message exceeds limit " + Str(limits_.max_message_bytes) + " bytes");
  }
  p.bytes.insert(p.bytes.end(), frame.payload.begin(), frame.payload.end());
  if (more) return OkStatus();
  Header h = p.first;
  h.flags = static_cast<uint16_t>(h.flags & ~kFlagMoreFragments);
  h.payload_length = static_cast<uint32_t>(p.bytes.size());
  std::vector<uint8_t> bytes = std::move(p.bytes);
  partial_.erase(it);
  HOLO_ASSIGN_OR_RETURN(Payload payload, DecodePayload(h, bytes, limits_));
  *out = Message{h, std::move(payload)};
  *complete = true;
  return OkStatus();
}

}  // namespace holo::protocol
