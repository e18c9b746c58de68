// Replays the fuzz corpus (tests/protocol/corpus/: seeds plus every input a
// fuzzer run found interesting or crashing) through the same entry point as
// the libFuzzer target, so it runs under gcc and in the sanitizer build.
// Regenerate the seeds with: HOLO_WRITE_CORPUS=1 build/tests/protocol_fuzz_corpus_test
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "protocol/color_codec.h"
#include "protocol/depth_codec.h"
#include "protocol/fuzz_decoders.h"
#include "protocol/sample_messages.h"

namespace holo::protocol {
namespace {

const std::string kCorpusDir = std::string(HOLO_SOURCE_DIR) + "/tests/protocol/corpus";

std::vector<std::pair<std::string, std::vector<uint8_t>>> Seeds() {
  std::vector<std::pair<std::string, std::vector<uint8_t>>> seeds;
  std::vector<uint8_t> stream;
  uint32_t seq = 0;
  for (const Payload& p : test::SamplePayloads()) {
    Header h;
    h.sequence = seq++;
    const auto m = EncodeMessage(h, p);
    seeds.emplace_back(std::string("seed-message-") + std::to_string(seq) + "-" + MessageTypeName(TypeOf(p)),
                       FuzzInput(FuzzTarget::kMessage, m));
    stream.insert(stream.end(), m.begin(), m.end());
  }
  MeshFrame big;
  big.data.assign(3000, 7);
  for (const auto& f : EncodeFragmented({}, big, 1000)) stream.insert(stream.end(), f.begin(), f.end());
  seeds.emplace_back("seed-stream", FuzzInput(FuzzTarget::kStream, stream));
  for (auto& seed : test::SampleCodecInputs(6, 9, 24, 18)) seeds.push_back(std::move(seed));
  return seeds;
}

// Seeds of holoport-fuzz-pod-frame (protocol/fuzz/corpus/pod_frame): PodFrame
// payloads with depth D1 and D2 (noisy slopes, invalid pixels and runs of
// them, extremes) and a C1 colour image.
std::vector<std::pair<std::string, std::vector<uint8_t>>> PodFrameSeeds() {
  std::vector<std::pair<std::string, std::vector<uint8_t>>> seeds;
  struct Spec {
    const char* name;
    DepthCodec codec;
    int w, h, noise_um;
  };
  for (const Spec& sp : {Spec{"seed-pod-frame-d1", DepthCodec::kD1, 24, 18, 3000},
                         Spec{"seed-pod-frame-d2", DepthCodec::kD2, 24, 18, 3000},
                         Spec{"seed-pod-frame-d2-wide", DepthCodec::kD2, 40, 6, 3000},
                         Spec{"seed-pod-frame-d2-quiet-sensor", DepthCodec::kD2, 12, 12, 500}}) {
    ImageDepth16 depth(sp.w, sp.h);
    uint32_t lcg = 12345;
    for (int y = 0; y < sp.h; ++y)
      for (int x = 0; x < sp.w; ++x) {
        lcg = lcg * 1664525u + 1013904223u;
        const int noise = static_cast<int>((lcg >> 24) % 61) - 30;
        const bool hole = (lcg >> 8) % 11 == 0 || (x >= sp.w - 3 && y < 4);
        depth.at(x, y) = hole ? 0 : static_cast<uint16_t>(x < sp.w / 2 ? 1200 + 4 * x + noise : 3500 - 9 * y + noise);
      }
    depth.at(0, sp.h - 1) = 65535;
    PodFrame f;
    f.pod_id = 1;
    f.frame_number = 5;
    f.capture_time_us = 1700000000;
    f.depth_codec = sp.codec;
    DepthEncodeOptions o;
    o.codec = sp.codec;
    o.noise_at_1m_um = sp.noise_um;
    HOLO_CHECK(EncodeDepth(depth, o, &f.depth).ok());
    HOLO_CHECK(EncodeColor(ImageRgb8(sp.w, sp.h, 77), ImageGray8(), {}, &f.color).ok());
    seeds.emplace_back(sp.name, EncodePayload(f));
  }
  return seeds;
}

TEST(FuzzCorpus, PodFrameSeedsDecodeDepthAndColour) {
  const std::string dir = std::string(HOLO_SOURCE_DIR) + "/protocol/fuzz/corpus/pod_frame";
  if (std::getenv("HOLO_WRITE_CORPUS")) {
    std::filesystem::create_directories(dir);
    for (const auto& [name, bytes] : PodFrameSeeds()) {
      std::ofstream(dir + "/" + name, std::ios::binary)
          .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    }
  }
  for (const auto& [name, bytes] : PodFrameSeeds()) EXPECT_EQ(FuzzPodFrame(bytes), 3) << name;
  // The files in the corpus (seeds: message, depth and colour all decode).
  int seeds = 0, d2 = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    std::ifstream in(entry.path(), std::ios::binary);
    const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    const int decoded = FuzzPodFrame(bytes);  // must not crash
    if (entry.path().filename().string().rfind("seed-", 0) == 0) {
      EXPECT_EQ(decoded, 3) << entry.path();
      ++seeds;
      d2 += entry.path().filename().string().find("-d2") != std::string::npos;
    }
  }
  EXPECT_GE(seeds, 4);
  EXPECT_GE(d2, 3);
}

TEST(FuzzCorpus, SeedsDecode) {
  if (std::getenv("HOLO_WRITE_CORPUS")) {
    std::filesystem::create_directories(kCorpusDir);
    for (const auto& [name, bytes] : Seeds()) {
      std::ofstream(kCorpusDir + "/" + name, std::ios::binary)
          .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
    }
  }
  for (const auto& [name, bytes] : Seeds()) EXPECT_GE(FuzzDecoders(bytes.data(), bytes.size()), 1) << name;
}

TEST(FuzzCorpus, ReplayCorpusDirectory) {
  ASSERT_TRUE(std::filesystem::is_directory(kCorpusDir)) << kCorpusDir;
  int files = 0;
  for (const auto& entry : std::filesystem::directory_iterator(kCorpusDir)) {
    if (!entry.is_regular_file()) continue;
    std::ifstream in(entry.path(), std::ios::binary);
    std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::unique_ptr<uint8_t[]> buf(new uint8_t[bytes.size() + 1]);
    std::copy(bytes.begin(), bytes.end(), buf.get());
    FuzzDecoders(buf.get(), bytes.size());  // must not crash; seeds must decode
    if (entry.path().filename().string().rfind("seed-", 0) == 0) {
      EXPECT_GE(FuzzDecoders(buf.get(), bytes.size()), 1) << entry.path();
    }
    ++files;
  }
  EXPECT_GT(files, 10);
}

// The corpora of the per-decoder libFuzzer targets (protocol/fuzz/corpus/NAME:
// seeds plus inputs kept from fuzz runs) through the same entry points.
TEST(FuzzCorpus, ReplayPerDecoderCorpora) {
  const std::string base = std::string(HOLO_SOURCE_DIR) + "/protocol/fuzz/corpus/";
  const std::vector<std::pair<std::string, int (*)(std::span<const uint8_t>)>> decoders = {
      {"stream", FuzzStream}, {"message", FuzzMessage}, {"geometry", FuzzGeometry}, {"color", FuzzColor}};
  for (const auto& [name, fn] : decoders) {
    ASSERT_TRUE(std::filesystem::is_directory(base + name)) << base + name;
    int seeds = 0;
    for (const auto& entry : std::filesystem::directory_iterator(base + name)) {
      if (!entry.is_regular_file()) continue;
      std::ifstream in(entry.path(), std::ios::binary);
      const std::vector<uint8_t> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
      const int decoded = fn(bytes);  // must not crash
      if (entry.path().filename().string().rfind("seed-", 0) == 0) {
        EXPECT_GE(decoded, 1) << entry.path();
        ++seeds;
      }
    }
    EXPECT_GE(seeds, 1) << name;
  }
}

}  // namespace
}  // namespace holo::protocol
