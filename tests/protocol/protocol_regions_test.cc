// Regions (message type 15): round trip, pinned bytes, every field's
// violation named, every truncated prefix and random bit flips, and the
// seeds of the holoport-fuzz-regions corpus.
#include <gtest/gtest.h>

#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <random>

#include "protocol/byte_io.h"
#include "protocol/fuzz_decoders.h"
#include "protocol/messages.h"
#include "protocol/sample_messages.h"

namespace holo::protocol {
namespace {

const std::string kCorpusDir = std::string(HOLO_SOURCE_DIR) + "/protocol/fuzz/corpus/regions";

std::unique_ptr<uint8_t[]> Fresh(const std::vector<uint8_t>& src, size_t n) {
  std::unique_ptr<uint8_t[]> p(new uint8_t[n == 0 ? 1 : n]);
  if (n) std::memcpy(p.get(), src.data(), n);
  return p;
}

StatusOr<Regions> Decode(const std::vector<uint8_t>& bytes) {
  auto p = DecodePayload(MessageType::kRegions, bytes);
  if (!p.ok()) return p.status();
  return std::get<Regions>(*p);
}

std::vector<std::pair<std::string, std::vector<uint8_t>>> Seeds() {
  std::vector<std::pair<std::string, std::vector<uint8_t>>> seeds;
  seeds.emplace_back("seed-regions-two", EncodePayload(test::SampleRegions()));
  Regions none;
  none.frame_index = 7;
  seeds.emplace_back("seed-regions-none", EncodePayload(none));
  Regions many;
  many.frame_index = 1234567;
  for (int i = 0; i < 5; ++i) {
    RegionReport r;
    r.name = "region-" + std::to_string(i);
    r.shape = i % 2 ? RegionShape::kSphere : RegionShape::kBox;
    r.a = {0.1f * i, -0.2f, 0.5f};
    r.b = i % 2 ? std::array<float, 3>{0.3f, 0, 0} : std::array<float, 3>{0.1f * i + 0.4f, 0.2f, 1.5f};
    r.state = static_cast<RegionState>(i % 4);
    r.occupied_litres = 0.5f * i;
    many.regions.push_back(r);
  }
  seeds.emplace_back("seed-regions-five", EncodePayload(many));
  return seeds;
}

TEST(RegionsMessage, RoundTripsThroughAWholeMessage) {
  const Regions m = test::SampleRegions();
  Header h;
  h.stream_id = 1;
  h.sequence = 42;
  h.capture_time_us = 1000;
  auto decoded = DecodeMessage(EncodeMessage(h, m));
  ASSERT_TRUE(decoded.ok()) << decoded.status().message();
  EXPECT_EQ(decoded->header.type, MessageType::kRegions);
  EXPECT_EQ(std::get<Regions>(decoded->payload), m);
  EXPECT_STREQ(MessageTypeName(MessageType::kRegions), "regions");
  EXPECT_TRUE(IsKnownMessageType(15));
  EXPECT_FALSE(IsKnownMessageType(16));
}

TEST(RegionsMessage, GoldenBytes) {
  Regions m;
  m.frame_index = 5;
  RegionReport r;
  r.name = "ab";
  r.shape = RegionShape::kSphere;
  r.a = {0, 0, 1.0f};
  r.b = {0.5f, 0, 0};
  r.state = RegionState::kStay;
  r.occupied_litres = 2.0f;
  m.regions = {r};
  const std::vector<uint8_t> expect = {
      0x05, 0, 0, 0, 0, 0, 0, 0,                        // frame_index
      0x01,                                             // count
      0x02, 'a', 'b',                                   // str8 name
      0x02,                                             // shape: sphere
      0, 0, 0, 0, 0, 0, 0, 0, 0x00, 0x00, 0x80, 0x3F,  // centre (0, 0, 1)
      0x00, 0x00, 0x00, 0x3F,                           // radius 0.5
      0x02,                                             // state: stay
      0x00, 0x00, 0x00, 0x40};                          // 2 litres
  EXPECT_EQ(EncodePayload(m), expect);
  auto d = Decode(expect);
  ASSERT_TRUE(d.ok()) << d.status().message();
  EXPECT_EQ(*d, m);
}

TEST(RegionsMessage, ViolationsNameTheField) {
  auto expect_error = [](const Regions& m, const std::function<void(std::vector<uint8_t>&)>& damage,
                         const std::string& field) {
    std::vector<uint8_t> b = EncodePayload(m);
    damage(b);
    auto d = Decode(b);
    ASSERT_FALSE(d.ok()) << field;
    EXPECT_NE(d.status().message().find(field), std::string::npos) << d.status().message();
  };
  const Regions m = test::SampleRegions();  // box "table" first: name at 9, shape at 15, a at 16, b at 28
  expect_error(m, [](auto& b) { b[7] = 0x80; }, "regions.frame_index");
  expect_error(m, [](auto& b) { b[8] = 65; }, "regions.count");
  expect_error(m, [](auto& b) { b[8] = 3; }, "regions.count");  // more regions than bytes
  expect_error(m, [](auto& b) { b[9] = 0; }, "regions.");          // empty name (then misaligned)
  expect_error(m, [](auto& b) { b[15] = 3; }, "regions.shape");
  expect_error(m, [](auto& b) { std::memcpy(&b[28], &b[16], 4); }, "regions.b");  // max x == min x
  {
    Regions twice = m;
    twice.regions[1].name = "table";
    expect_error(twice, [](auto&) {}, "appears twice");
  }
  {
    Regions bad = m;
    bad.regions[1].b[0] = -1.0f;
    expect_error(bad, [](auto&) {}, "regions.radius");
  }
  {
    Regions bad = m;
    bad.regions[0].state = static_cast<RegionState>(4);
    expect_error(bad, [](auto&) {}, "regions.state");
  }
  {
    Regions bad = m;
    bad.regions[0].occupied_litres = -0.5f;
    expect_error(bad, [](auto&) {}, "regions.occupied_litres");
  }
  {
    Regions bad = m;
    bad.regions[0].a[1] = std::numeric_limits<float>::quiet_NaN();
    expect_error(bad, [](auto&) {}, "regions.a");
  }
  expect_error(m, [](auto& b) { b.push_back(0); }, "regions");  // trailing byte
}

TEST(RegionsMessage, EveryTruncatedPrefixIsAnError) {
  for (const auto& [name, bytes] : Seeds()) {
    for (size_t n = 0; n < bytes.size(); ++n) {
      auto buf = Fresh(bytes, n);
      EXPECT_FALSE(DecodePayload(MessageType::kRegions, {buf.get(), n}).ok()) << name << " prefix " << n;
    }
  }
}

TEST(RegionsMessage, RandomBitFlipsNeverCrash) {
  const auto seeds = Seeds();
  std::mt19937 rng(2026);
  int decoded = 0;
  for (int i = 0; i < 20000; ++i) {
    std::vector<uint8_t> m = seeds[i % seeds.size()].second;
    const int flips = 1 + static_cast<int>(rng() % 3);
    for (int k = 0; k < flips; ++k) m[rng() % m.size()] ^= static_cast<uint8_t>(1u << (rng() % 8));
    auto buf = Fresh(m, m.size());
    decoded += FuzzRegions({buf.get(), m.size()});  // re-encodes what it accepts, aborts on a mismatch
  }
  EXPECT_GT(decoded, 0);  // flips in the floats' low bits still decode
}

TEST(RegionsMessage, FuzzCorpusSeedsDecode) {
  if (std::getenv("HOLO_WRITE_CORPUS")) {
    std::filesystem::create_directories(kCorpusDir);
    for (const auto& [name, bytes] : Seeds())
      std::ofstream(kCorpusDir + "/" + name, std::ios::binary)
          .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
  }
  for (const auto& [name, bytes] : Seeds()) EXPECT_EQ(FuzzRegions(bytes), 1) << name;
  int seeds = 0;
  for (const auto& entry : std::filesystem::directory_iterator(kCorpusDir)) {
    std::ifstream in(entry.path(), std::ios::binary);
    const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const int ok = FuzzRegions(bytes);  // must not crash
    if (entry.path().filename().string().rfind("seed-", 0) == 0) {
      EXPECT_EQ(ok, 1) << entry.path();
      ++seeds;
    }
  }
  EXPECT_GE(seeds, 3);
}

}  // namespace
}  // namespace holo::protocol
