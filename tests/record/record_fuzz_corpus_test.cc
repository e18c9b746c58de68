// Seeds of the recording fuzz target (protocol/fuzz/fuzz_recording.cc) and a
// replay of its corpus (protocol/fuzz/corpus/recording/: seeds plus inputs
// kept from fuzz runs) through the reader, so the normal and the sanitizer
// test runs cover every input a fuzz run kept.
// Regenerate the seeds with: HOLO_WRITE_CORPUS=1 build/tests/record_record_fuzz_corpus_test
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>

#include "record/record_test_util.h"
#include "server/record/recording_reader.h"
#include "test_util.h"

namespace holo::record {
namespace {

const std::string kCorpusDir = std::string(HOLO_SOURCE_DIR) + "/protocol/fuzz/corpus/recording";

TEST(RecordingFuzzCorpus, SeedsOpenAndReplayDoesNotCrash) {
  const std::string dir = test::MakeTempDir("record_fuzz_corpus");
  // A closed (indexed) and an unclosed (scanned) recording, small enough for a fuzzer.
  const auto msgs = test::MakeTestStream(3, 30, 2);
  test::WriteTestRecording(dir + "/seed-closed.hrec", msgs, true);
  test::WriteTestRecording(dir + "/seed-unclosed.hrec", msgs, false);
  for (const char* name : {"seed-closed.hrec", "seed-unclosed.hrec"}) {
    auto r = RecordingReader::Open(dir + "/" + name);
    ASSERT_TRUE(r.ok()) << name << ": " << r.status().ToString();
    EXPECT_GE((*r)->summary().num_messages, 1u) << name;
    if (std::getenv("HOLO_WRITE_CORPUS")) {
      std::filesystem::create_directories(kCorpusDir);
      std::filesystem::copy_file(dir + "/" + name, kCorpusDir + "/" + name,
                                 std::filesystem::copy_options::overwrite_existing);
    }
  }
  ASSERT_TRUE(std::filesystem::is_directory(kCorpusDir)) << kCorpusDir;
  for (const auto& entry : std::filesystem::directory_iterator(kCorpusDir)) {
    if (!entry.is_regular_file()) continue;
    RecordingReaderOptions options;
    options.salvage = true;
    auto r = RecordingReader::Open(entry.path().string(), options);  // must not crash
    if (!r.ok()) continue;
    uint64_t offset = (*r)->summary().data_begin;
    for (uint64_t i = 0; i < (*r)->summary().num_messages; ++i) {
      auto m = (*r)->ReadAt(offset);
      if (!m.ok()) break;
      ASSERT_GT(m->next_offset, offset) << entry.path();
      offset = m->next_offset;
    }
  }
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace holo::record
