// RecordingSink: frames as a recorder client receives them (fragmented,
// interleaved, with session messages) become whole recorded messages.
#include <gtest/gtest.h>

#include "record/record_test_util.h"
#include "server/record/recording_reader.h"
#include "server/record/recording_sink.h"
#include "test_util.h"

namespace holo::record {
namespace {

using protocol::MessageType;

// Cuts wire bytes into frames the way a connection does.
std::vector<protocol::Frame> Frames(const std::vector<uint8_t>& wire) {
  protocol::FrameParser parser;
  HOLO_CHECK(parser.Feed(wire.data(), wire.size()).ok());
  std::vector<protocol::Frame> out;
  protocol::Frame f;
  while (parser.Next(&f)) out.push_back(std::move(f));
  return out;
}

void Append(std::vector<uint8_t>* wire, const std::vector<uint8_t>& bytes) {
  wire->insert(wire->end(), bytes.begin(), bytes.end());
}

TEST(RecordSink, ReassemblesInterleavedFragmentsIntoWholeMessages) {
  const std::string dir = test::MakeTempDir("record_sink");
  const auto msgs = test::MakeTestStream(8, 30, 8);  // meshes of a few kB
  // The wire: a Welcome, a mesh before the Rig, the Rig, then every mesh in
  // 700-byte fragments with the audio frames slipped between fragments.
  std::vector<uint8_t> wire;
  protocol::Header h;
  Append(&wire, protocol::EncodeMessage(h, protocol::Welcome{}));
  Append(&wire, msgs.back().frame);
  std::vector<std::vector<uint8_t>> expected;  // in completion order
  std::vector<std::vector<uint8_t>> audio;
  for (const auto& m : msgs) {
    if (m.type == MessageType::kRig) {
      Append(&wire, m.frame);
      expected.push_back(m.frame);
    } else if (m.type == MessageType::kAudioPose) {
      audio.push_back(m.frame);
    } else {
      auto dec = protocol::DecodeMessage(m.frame);
      ASSERT_TRUE(dec.ok());
      const auto frags = protocol::EncodeFragmented(dec->header, dec->payload, 100);
      ASSERT_GT(frags.size(), 1u);
      for (size_t i = 0; i < frags.size(); ++i) {
        Append(&wire, frags[i]);
        if (i == 0 && !audio.empty()) {  // audio overtakes the video frame
          for (const auto& a : audio) {
            Append(&wire, a);
            expected.push_back(a);
          }
          audio.clear();
        }
      }
      expected.push_back(m.frame);
      Append(&wire, protocol::EncodeMessage(h, protocol::Ping{7, 8}));
    }
  }
  {
    auto w = RecordingWriter::Create(dir + "/s.hrec", RecordingWriterOptions{});
    ASSERT_TRUE(w.ok());
    RecordingSink sink(w->get());
    int64_t now = 5000000;
    for (const auto& f : Frames(wire)) {
      ASSERT_TRUE(sink.AddFrame(f, now).ok());
      now += 1000;
    }
    EXPECT_EQ(sink.stats().recorded, expected.size());
    EXPECT_EQ(sink.stats().before_rig, 1u);
    EXPECT_GE(sink.stats().ignored_types, 9u);  // Welcome + Pings
    EXPECT_EQ(sink.stats().rejected, 0u);
    ASSERT_TRUE((*w)->Close().ok());
  }
  auto r = RecordingReader::Open(dir + "/s.hrec");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  size_t i = 0;
  int64_t last = -1;
  for (uint64_t at = (*r)->summary().data_begin; at < (*r)->summary().data_end; ++i) {
    auto m = (*r)->ReadAt(at);
    ASSERT_TRUE(m.ok());
    at = m->next_offset;
    ASSERT_LT(i, expected.size());
    EXPECT_EQ(*m->bytes, expected[i]) << i;  // the whole message, byte-identical to the unfragmented encoding
    EXPECT_GE(m->time_us, last);
    last = m->time_us;
  }
  EXPECT_EQ(i, expected.size());
  EXPECT_EQ((*r)->summary().index.size(), 8u);
}

TEST(RecordSink, MalformedFragmentsAndTheEndOfTheRecording) {
  const std::string dir = test::MakeTempDir("record_sink_bad");
  const auto msgs = test::MakeTestStream(3, 30, 8);  // a mesh of a few hundred bytes
  auto w = RecordingWriter::Create(dir + "/b.hrec", RecordingWriterOptions{});
  ASSERT_TRUE(w.ok());
  RecordingSink sink(w->get(), 64u << 20, 2);
  ASSERT_TRUE(sink.AddFrame(Frames(msgs[0].frame)[0], 0).ok());
  auto dec = protocol::DecodeMessage(msgs.back().frame);
  ASSERT_TRUE(dec.ok());
  auto frags = protocol::EncodeFragmented(dec->header, dec->payload, 100);
  ASSERT_TRUE(sink.AddFrame(Frames(frags[0])[0], 1).ok());
  // Another sequence for the same (stream, type) while one is in progress.
  auto other = Frames(frags[1])[0];
  other.header.sequence += 1;
  EXPECT_EQ(sink.AddFrame(other, 2).code(), StatusCode::kDataLoss);
  // Too many messages in progress.
  protocol::Frame f = Frames(frags[0])[0];
  f.header.stream_id = 50;
  ASSERT_TRUE(sink.AddFrame(f, 3).ok());
  f.header.stream_id = 51;
  EXPECT_EQ(sink.AddFrame(f, 3).code(), StatusCode::kDataLoss);
  // Payload size that does not match the header.
  f.payload.pop_back();
  EXPECT_EQ(sink.AddFrame(f, 3).code(), StatusCode::kDataLoss);

  // The size limit ends the recording through the sink.
  RecordingWriterOptions o;
  o.max_bytes = 20000;
  auto lw = RecordingWriter::Create(dir + "/l.hrec", o);
  ASSERT_TRUE(lw.ok());
  RecordingSink limited(lw->get());
  const auto many = test::MakeTestStream(100, 30, 8);
  Status s;
  for (const auto& m : many) {
    s = limited.AddFrame(Frames(m.frame)[0], m.time_us);
    if (!s.ok()) break;
  }
  EXPECT_EQ(s.code(), StatusCode::kOutOfRange) << s.ToString();
  auto r = RecordingReader::Open(dir + "/l.hrec");
  ASSERT_TRUE(r.ok());
  EXPECT_EQ((*r)->summary().num_messages, limited.stats().recorded);
}

}  // namespace
}  // namespace holo::record
