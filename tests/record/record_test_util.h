// Small hand-made recordings for the recording tests.
#pragma once

#include <sys/stat.h>
#include <unistd.h>

#include <cstdint>
#include <fstream>
#include <string>
#include <vector>

#include "protocol/geometry_codec.h"
#include "protocol/messages.h"
#include "protocol/sample_messages.h"
#include "protocol/test_meshes.h"
#include "server/record/recording_writer.h"

namespace holo::test {

struct TestMessage {
  int64_t time_us = 0;
  std::vector<uint8_t> frame;
  protocol::MessageType type = protocol::MessageType::kPing;
};

// A stream of `frames` video frames at `fps` (MeshFrame key frames of a small
// sphere, one ColorFrame-free stream), the Rig first, 20 ms PCM AudioPose
// frames (8 kHz) interleaved; `sphere` rows/cols scale the mesh size.
inline std::vector<TestMessage> MakeTestStream(int frames, double fps = 30, int sphere = 4) {
  using namespace protocol;
  std::vector<TestMessage> out;
  Header h;
  out.push_back({0, EncodeMessage(h, RigMessage{SampleRig()}), MessageType::kRig});
  const Mesh mesh = NoisySphere(sphere, sphere);
  uint32_t audio_seq = 0;
  int64_t next_audio = 0;
  for (int f = 0; f < frames; ++f) {
    const int64_t t = static_cast<int64_t>(static_cast<double>(f) * 1e6 / fps + 0.5);
    while (next_audio < t) {
      AudioPose a;
      a.codec = AudioCodec::kPcm16;
      a.sample_rate = 8000;
      a.sequence = audio_seq;
      a.capture_time_us = next_audio;
      a.audio.assign(320, static_cast<uint8_t>(audio_seq));
      Header ah;
      ah.stream_id = 2;
      ah.sequence = audio_seq++;
      ah.capture_time_us = next_audio;
      out.push_back({next_audio, EncodeMessage(ah, a), MessageType::kAudioPose});
      next_audio += 20000;
    }
    MeshFrame mf;
    mf.frame_index = f;
    HOLO_CHECK(EncodeGeometry(mesh, GeometryEncodeOptions{}, &mf.data).ok());
    Header mh;
    mh.stream_id = 1;
    mh.sequence = static_cast<uint32_t>(f);
    mh.capture_time_us = t;
    mh.flags = kFlagKeyFrame;
    out.push_back({t, EncodeMessage(mh, mf), MessageType::kMeshFrame});
  }
  return out;
}

inline void WriteTestRecording(const std::string& path, const std::vector<TestMessage>& msgs, bool close = true) {
  record::RecordingWriterOptions o;
  o.source = "test";
  auto w = record::RecordingWriter::Create(path, o, /*overwrite=*/true);
  HOLO_CHECK_MSG(w.ok(), w.status().ToString());
  for (const auto& m : msgs) {
    Status s = (*w)->WriteMessage(m.time_us, m.frame);
    HOLO_CHECK_MSG(s.ok(), s.ToString());
  }
  if (close) HOLO_CHECK((*w)->Close().ok());
}

inline std::vector<uint8_t> ReadBytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return std::vector<uint8_t>(std::istreambuf_iterator<char>(f), {});
}

// Writes a fresh file (unlinked first: rewriting a truncated file makes ext4
// flush it on close, which is slow on a busy disk).
inline void WriteBytes(const std::string& path, const std::vector<uint8_t>& b, size_t n) {
  ::unlink(path.c_str());
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f.write(reinterpret_cast<const char*>(b.data()), static_cast<std::streamsize>(n));
}

}  // namespace holo::test
