// The recording container: byte-identical round trip, crash safety (every
// truncation, kill -9 mid-write), size limit, full disk, corrupt and absurd
// files.
#include <signal.h>
#include <sys/mount.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstring>
#include <filesystem>
#include <thread>

#include <gtest/gtest.h>

#include "record/record_test_util.h"
#include "server/record/recording_format.h"
#include "server/record/recording_reader.h"
#include "server/record/recording_writer.h"
#include "test_util.h"

namespace holo::record {
namespace {

using test::MakeTestStream;
using test::ReadBytes;
using test::TestMessage;
using test::WriteBytes;
using test::WriteTestRecording;

// Reads every message of a recording in file order.
std::vector<RecordedMessage> ReadAll(const RecordingReader& r, Status* error = nullptr) {
  std::vector<RecordedMessage> out;
  uint64_t at = r.summary().data_begin;
  while (at < r.summary().data_end) {
    auto m = r.ReadAt(at);
    if (!m.ok()) {
      if (error) *error = m.status();
      break;
    }
    at = m->next_offset;
    out.push_back(std::move(*m));
  }
  return out;
}

void ExpectPrefix(const std::vector<RecordedMessage>& got, const std::vector<TestMessage>& want) {
  ASSERT_LE(got.size(), want.size());
  for (size_t i = 0; i < got.size(); ++i) {
    ASSERT_EQ(*got[i].bytes, want[i].frame) << "message " << i;
    ASSERT_EQ(got[i].time_us, want[i].time_us) << "message " << i;
  }
}

TEST(RecordFormat, Crc32cKnownValue) {
  const char* s = "123456789";
  EXPECT_EQ(Crc32c(0, reinterpret_cast<const uint8_t*>(s), 9), 0xE3069283u);
  // Incremental equals one-shot.
  const uint32_t a = Crc32c(0, reinterpret_cast<const uint8_t*>(s), 4);
  EXPECT_EQ(Crc32c(a, reinterpret_cast<const uint8_t*>(s) + 4, 5), 0xE3069283u);
}

TEST(RecordFormat, RoundTripIsByteIdentical) {
  const std::string dir = test::MakeTempDir("record_rt");
  const auto msgs = MakeTestStream(45);
  WriteTestRecording(dir + "/a.hrec", msgs);
  auto r = RecordingReader::Open(dir + "/a.hrec");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const auto& s = (*r)->summary();
  EXPECT_TRUE(s.clean);
  EXPECT_EQ(s.num_messages, msgs.size());
  EXPECT_EQ(s.duration_us, msgs.back().time_us);
  EXPECT_EQ(s.file.source, "test");
  EXPECT_EQ((*r)->rig().name, "test-rig");
  ASSERT_EQ(s.index.size(), 45u);
  auto got = ReadAll(**r);
  ASSERT_EQ(got.size(), msgs.size());
  ExpectPrefix(got, msgs);
  // The index points at every key frame, with the Rig as the rig in effect.
  size_t k = 0;
  for (const auto& m : got) {
    if (m.header.type != protocol::MessageType::kMeshFrame) continue;
    ASSERT_LT(k, s.index.size());
    EXPECT_EQ(s.index[k].offset, m.offset);
    EXPECT_EQ(s.index[k].time_us, m.time_us);
    EXPECT_EQ(s.index[k].rig_offset, s.data_begin);
    ++k;
  }
  // Every recorded message decodes as a protocol message.
  for (const auto& m : got) ASSERT_TRUE(protocol::DecodeMessage(*m.bytes).ok());
}

TEST(RecordFormat, UnclosedFileIsScannedAndIndexRebuilt) {
  const std::string dir = test::MakeTempDir("record_unclosed");
  const auto msgs = MakeTestStream(20);
  WriteTestRecording(dir + "/clean.hrec", msgs);
  const auto clean = RecordingReader::Open(dir + "/clean.hrec");
  ASSERT_TRUE(clean.ok());
  // The same bytes without the footer = a recorder that was killed.
  const auto bytes = ReadBytes(dir + "/clean.hrec");
  WriteBytes(dir + "/crashed.hrec", bytes, (*clean)->summary().data_end);
  auto r = RecordingReader::Open(dir + "/crashed.hrec");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_FALSE((*r)->summary().clean);
  EXPECT_EQ((*r)->summary().ignored_tail_bytes, 0u);
  EXPECT_EQ((*r)->summary().index, (*clean)->summary().index);
  EXPECT_EQ((*r)->summary().num_messages, msgs.size());
  EXPECT_EQ((*r)->summary().duration_us, (*clean)->summary().duration_us);
}

// Crash at any byte: the file opens and holds exactly the complete messages.
TEST(RecordFormat, TruncatedAtEveryByteKeepsEveryCompleteMessage) {
  const std::string dir = test::MakeTempDir("record_trunc");
  const auto msgs = MakeTestStream(6, 30, 3);
  WriteTestRecording(dir + "/full.hrec", msgs);
  const auto bytes = ReadBytes(dir + "/full.hrec");
  auto full = RecordingReader::Open(dir + "/full.hrec");
  ASSERT_TRUE(full.ok());
  const auto all = ReadAll(**full);
  ASSERT_EQ(all.size(), msgs.size());
  size_t opened = 0;
  for (size_t n = 0; n <= bytes.size(); ++n) {
    WriteBytes(dir + "/cut.hrec", bytes, n);
    size_t complete = 0;
    while (complete < all.size() && all[complete].next_offset <= n) ++complete;
    auto r = RecordingReader::Open(dir + "/cut.hrec");
    if (complete == 0) {
      ASSERT_FALSE(r.ok()) << "n=" << n;
      EXPECT_EQ(r.status().code(), StatusCode::kDataLoss) << r.status().ToString();
      continue;
    }
    ASSERT_TRUE(r.ok()) << "n=" << n << ": " << r.status().ToString();
    ++opened;
    EXPECT_EQ((*r)->summary().clean, n == bytes.size()) << n;
    ASSERT_EQ((*r)->summary().num_messages, complete) << "n=" << n;
    Status error;
    const auto got = ReadAll(**r, &error);
    ASSERT_TRUE(error.ok()) << error.ToString();
    ASSERT_EQ(got.size(), complete);
    ExpectPrefix(got, msgs);
    size_t keys = 0;
    for (size_t i = 0; i < complete; ++i) keys += msgs[i].type == protocol::MessageType::kMeshFrame;
    EXPECT_EQ((*r)->summary().index.size(), keys);
  }
  EXPECT_GT(opened, bytes.size() / 2);
}

// A writer process killed with SIGKILL while writing as fast as it can.
TEST(RecordFormat, KillNineMidWriteReplaysUpToLastCompleteMessage) {
  const std::string dir = test::MakeTempDir("record_kill");
  const std::string path = dir + "/killed.hrec";
  const auto msgs = MakeTestStream(3000, 30, 6);
  const pid_t pid = fork();
  ASSERT_GE(pid, 0);
  if (pid == 0) {
    RecordingWriterOptions o;
    o.sync_every_bytes = 0;
    auto w = RecordingWriter::Create(path, o);
    if (!w.ok()) _exit(2);
    for (const auto& m : msgs)
      if (!(*w)->WriteMessage(m.time_us, m.frame).ok()) _exit(3);
    // Never close: wait to be killed.
    for (;;) pause();
  }
  // Kill it while it writes (once the file has some size, or at worst when done).
  struct stat st {};
  for (int i = 0; i < 4000; ++i) {
    if (stat(path.c_str(), &st) == 0 && st.st_size > 200000) break;
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  ASSERT_EQ(kill(pid, SIGKILL), 0);
  int status = 0;
  ASSERT_EQ(waitpid(pid, &status, 0), pid);
  ASSERT_TRUE(WIFSIGNALED(status)) << "writer exited early with " << WEXITSTATUS(status);
  auto r = RecordingReader::Open(path);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_FALSE((*r)->summary().clean);
  Status error;
  const auto got = ReadAll(**r, &error);
  ASSERT_TRUE(error.ok()) << error.ToString();
  EXPECT_GT(got.size(), 10u);
  ExpectPrefix(got, msgs);
  std::printf("killed writer after %zu of %zu messages (%llu bytes; torn tail %llu bytes)\n", got.size(), msgs.size(),
              static_cast<unsigned long long>((*r)->summary().data_end),
              static_cast<unsigned long long>((*r)->summary().ignored_tail_bytes));
}

TEST(RecordFormat, SizeLimitClosesTheRecordingKeepingEverything) {
  const std::string dir = test::MakeTempDir("record_limit");
  const auto msgs = MakeTestStream(200);
  RecordingWriterOptions o;
  o.max_bytes = 30000;
  auto w = RecordingWriter::Create(dir + "/l.hrec", o);
  ASSERT_TRUE(w.ok());
  size_t written = 0;
  Status s;
  for (const auto& m : msgs) {
    s = (*w)->WriteMessage(m.time_us, m.frame);
    if (!s.ok()) break;
    ++written;
  }
  ASSERT_EQ(s.code(), StatusCode::kOutOfRange) << s.ToString();
  EXPECT_NE(s.message().find("size limit"), std::string::npos) << s.message();
  EXPECT_EQ((*w)->WriteMessage(msgs.back().time_us, msgs.back().frame).code(), StatusCode::kOutOfRange);
  EXPECT_TRUE((*w)->Close().ok());
  EXPECT_LE(std::filesystem::file_size(dir + "/l.hrec"), o.max_bytes);
  EXPECT_GT(std::filesystem::file_size(dir + "/l.hrec"), o.max_bytes - 1000);
  auto r = RecordingReader::Open(dir + "/l.hrec");
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_TRUE((*r)->summary().clean);
  EXPECT_EQ((*r)->summary().num_messages, written);
  ExpectPrefix(ReadAll(**r), msgs);
}

// A file in memory that runs out of space after `budget` bytes.
class FullDiskFile final : public RecordingFile {
 public:
  FullDiskFile(std::vector<uint8_t>* data, size_t budget) : data_(data), budget_(budget) {}
  Status WriteAll(const iovec* iov, int count, bool* enospc) override {
    for (int i = 0; i < count; ++i) {
      const auto* p = static_cast<const uint8_t*>(iov[i].iov_base);
      for (size_t k = 0; k < iov[i].iov_len; ++k) {
        if (data_->size() >= budget_) {
          *enospc = true;
          return Unavailable("injected: No space left on device");
        }
        data_->push_back(p[k]);
      }
    }
    return OkStatus();
  }
  Status Truncate(uint64_t size) override {
    data_->resize(size);
    return OkStatus();
  }
  Status Sync() override { return OkStatus(); }
  Status Close() override { return OkStatus(); }

 private:
  std::vector<uint8_t>* data_;
  size_t budget_;
};

TEST(RecordFormat, FullDiskAtAnyPointKeepsEarlierMessages) {
  const std::string dir = test::MakeTempDir("record_enospc");
  const auto msgs = MakeTestStream(12, 30, 3);
  size_t total = 0;
  for (const auto& m : msgs) total += kRecordHeaderSize + m.frame.size();
  for (size_t budget = 0; budget < total + 2000; budget += 37) {
    std::vector<uint8_t> data;
    auto w = RecordingWriter::Create(std::make_unique<FullDiskFile>(&data, budget), RecordingWriterOptions{});
    if (budget < kFileHeaderSize) {
      ASSERT_FALSE(w.ok());
      EXPECT_NE(w.status().message().find("disk full"), std::string::npos) << w.status().message();
      continue;
    }
    ASSERT_TRUE(w.ok()) << budget;
    Status s;
    for (const auto& m : msgs) {
      s = (*w)->WriteMessage(m.time_us, m.frame);
      if (!s.ok()) break;
    }
    const uint64_t written = (*w)->stats().messages;
    if (s.ok()) s = (*w)->Close();
    if (!s.ok()) {
      EXPECT_EQ(s.code(), StatusCode::kUnavailable);
      EXPECT_TRUE(s.message().find("disk full") != std::string::npos ||
                  s.message().find("index failed") != std::string::npos)
          << s.message();
    }
    w->reset();
    WriteBytes(dir + "/f.hrec", data, data.size());
    auto r = RecordingReader::Open(dir + "/f.hrec");
    if (written == 0) {
      EXPECT_FALSE(r.ok());
      continue;
    }
    ASSERT_TRUE(r.ok()) << "budget " << budget << ": " << r.status().ToString();
    EXPECT_EQ((*r)->summary().num_messages, written) << budget;
    EXPECT_EQ((*r)->summary().ignored_tail_bytes, 0u) << budget;
    ExpectPrefix(ReadAll(**r), msgs);
  }
}

// The real thing: a 96 KiB tmpfs (needs permission to mount; skipped otherwise).
TEST(RecordFormat, RealFullTmpfs) {
  const std::string dir = test::MakeTempDir("record_tmpfs");
  if (mount("tmpfs", dir.c_str(), "tmpfs", 0, "size=96k") != 0)
    GTEST_SKIP() << "cannot mount a tmpfs here (needs CAP_SYS_ADMIN; DevFullIsAClearError and the injected write "
                    "failures cover a full disk too): " << std::strerror(errno);
  const auto msgs = MakeTestStream(2000, 30, 6);
  Status s;
  uint64_t written = 0;
  {
    auto w = RecordingWriter::Create(dir + "/full.hrec", RecordingWriterOptions{});
    ASSERT_TRUE(w.ok()) << w.status().ToString();
    for (const auto& m : msgs) {
      s = (*w)->WriteMessage(m.time_us, m.frame);
      if (!s.ok()) break;
    }
    written = (*w)->stats().messages;
  }
  auto r = RecordingReader::Open(dir + "/full.hrec");
  const bool open_ok = r.ok();
  std::vector<RecordedMessage> got;
  if (open_ok) got = ReadAll(**r);
  r = Status(StatusCode::kInternal, "released");
  umount(dir.c_str());
  ASSERT_EQ(s.code(), StatusCode::kUnavailable) << s.ToString();
  EXPECT_NE(s.message().find("disk full"), std::string::npos) << s.message();
  std::printf("tmpfs full: %s\n", s.message().c_str());
  ASSERT_TRUE(open_ok);
  EXPECT_GT(written, 10u);
  EXPECT_EQ(got.size(), written);
  ExpectPrefix(got, msgs);
}

TEST(RecordFormat, DevFullIsAClearError) {
  // /dev/full is a Linux device; elsewhere the injected write failures above cover the same path.
  if (!std::filesystem::exists("/dev/full")) GTEST_SKIP() << "/dev/full does not exist on this system";
  auto f = OpenPosixRecordingFile("/dev/full", /*overwrite=*/true);
  ASSERT_TRUE(f.ok()) << f.status().ToString();
  auto w = RecordingWriter::Create(std::move(*f), RecordingWriterOptions{}, "/dev/full");
  ASSERT_FALSE(w.ok());
  EXPECT_EQ(w.status().code(), StatusCode::kUnavailable);
  EXPECT_NE(w.status().message().find("disk full"), std::string::npos) << w.status().message();
}

TEST(RecordFormat, WriterRejectsBadMessagesAndGoesOn) {
  const std::string dir = test::MakeTempDir("record_bad_in");
  const auto msgs = MakeTestStream(3);
  auto w = RecordingWriter::Create(dir + "/w.hrec", RecordingWriterOptions{});
  ASSERT_TRUE(w.ok());
  // Not the Rig first.
  EXPECT_EQ((*w)->WriteMessage(0, msgs[2].frame).code(), StatusCode::kInvalidArgument);
  ASSERT_TRUE((*w)->WriteMessage(0, msgs[0].frame).ok());
  // A fragment.
  auto frag = msgs.back().frame;
  frag[8] |= protocol::kFlagMoreFragments;
  EXPECT_EQ((*w)->WriteMessage(10, frag).code(), StatusCode::kInvalidArgument);
  // A Ping is not content.
  protocol::Header h;
  EXPECT_EQ((*w)->WriteMessage(10, protocol::EncodeMessage(h, protocol::Ping{1, 2})).code(),
            StatusCode::kInvalidArgument);
  // Length mismatch, short, corrupt payload.
  auto cut = msgs.back().frame;
  cut.pop_back();
  EXPECT_EQ((*w)->WriteMessage(10, cut).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ((*w)->WriteMessage(10, std::vector<uint8_t>(10)).code(), StatusCode::kInvalidArgument);
  auto bad = msgs.back().frame;
  bad[protocol::kHeaderSize + 8] = 9;  // MeshFrame codec 9
  EXPECT_EQ((*w)->WriteMessage(10, bad).code(), StatusCode::kInvalidArgument);
  ASSERT_TRUE((*w)->WriteMessage(50, msgs[1].frame).ok());
  // Time going back.
  EXPECT_EQ((*w)->WriteMessage(40, msgs[2].frame).code(), StatusCode::kInvalidArgument);
  ASSERT_TRUE((*w)->Close().ok());
  auto r = RecordingReader::Open(dir + "/w.hrec");
  ASSERT_TRUE(r.ok());
  EXPECT_EQ((*r)->summary().num_messages, 2u);
  // Refuses to overwrite an existing recording.
  auto again = RecordingWriter::Create(dir + "/w.hrec", RecordingWriterOptions{});
  ASSERT_FALSE(again.ok());
  EXPECT_NE(again.status().message().find("exists"), std::string::npos);
}

TEST(RecordFormat, CorruptAndAbsurdFilesGiveErrors) {
  const std::string dir = test::MakeTempDir("record_corrupt");
  const std::string p = dir + "/c.hrec";
  EXPECT_EQ(RecordingReader::Open(dir + "/missing.hrec").status().code(), StatusCode::kNotFound);
  EXPECT_FALSE(RecordingReader::Open(dir).ok());  // a directory
  WriteBytes(p, std::vector<uint8_t>(100, 0x41), 100);
  auto r = RecordingReader::Open(p);
  ASSERT_FALSE(r.ok());
  EXPECT_NE(r.status().message().find("magic"), std::string::npos) << r.status().message();

  // A future format version.
  FileHeader fh;
  fh.format_version = 2;
  std::vector<uint8_t> b(kFileHeaderSize);
  EncodeFileHeader(fh, b.data());
  WriteBytes(p, b, b.size());
  EXPECT_EQ(RecordingReader::Open(p).status().code(), StatusCode::kUnsupportedVersion);

  // A header alone holds no message.
  fh.format_version = kFormatVersion;
  EncodeFileHeader(fh, b.data());
  WriteBytes(p, b, b.size());
  EXPECT_EQ(RecordingReader::Open(p).status().code(), StatusCode::kDataLoss);

  // A first message that is not the Rig (written by hand).
  const auto msgs = MakeTestStream(3);
  {
    std::vector<uint8_t> f = b;
    const auto& m = msgs.back().frame;
    uint8_t rh[kRecordHeaderSize];
    EncodeRecordHeader(RecordKind::kMessage, 0, m, rh);
    f.insert(f.end(), rh, rh + kRecordHeaderSize);
    f.insert(f.end(), m.begin(), m.end());
    WriteBytes(p, f, f.size());
    auto x = RecordingReader::Open(p);
    ASSERT_FALSE(x.ok());
    EXPECT_NE(x.status().message().find("Rig"), std::string::npos) << x.status().message();
  }

  // An absurd index count with a valid checksum.
  WriteTestRecording(p, msgs);
  auto clean = RecordingReader::Open(p);
  ASSERT_TRUE(clean.ok());
  const uint64_t index_offset = (*clean)->summary().data_end;
  auto bytes = ReadBytes(p);
  {
    std::vector<uint8_t> f(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(index_offset));
    IndexBody ib;
    ib.num_messages = 1;
    ib.duration_us = 0;
    std::vector<uint8_t> body = EncodeIndexBody(ib);
    const uint32_t huge = 0x7FFFFFFF;
    std::memcpy(body.data() + 16, &huge, 4);
    uint8_t rh[kRecordHeaderSize];
    EncodeRecordHeader(RecordKind::kIndex, 0, body, rh);
    f.insert(f.end(), rh, rh + kRecordHeaderSize);
    f.insert(f.end(), body.begin(), body.end());
    uint8_t end[kEndRecordSize];
    std::memcpy(end + kRecordHeaderSize, &index_offset, 8);
    EncodeRecordHeader(RecordKind::kEnd, 0, std::span<const uint8_t>(end + kRecordHeaderSize, 8), end);
    f.insert(f.end(), end, end + kEndRecordSize);
    WriteBytes(p, f, f.size());
    auto x = RecordingReader::Open(p);
    ASSERT_FALSE(x.ok());
    EXPECT_NE(x.status().message().find("index.count"), std::string::npos) << x.status().message();
  }

  // Damage in the middle of an unclosed file: an error that says how to salvage.
  {
    std::vector<uint8_t> f(bytes.begin(), bytes.begin() + static_cast<std::ptrdiff_t>(index_offset));
    const auto all = [&] {
      WriteBytes(p, bytes, bytes.size());
      auto rr = RecordingReader::Open(p);
      return ReadAll(**rr);
    }();
    ASSERT_GE(all.size(), 4u);
    f[all[2].offset + kRecordHeaderSize + 40] ^= 0x10;
    WriteBytes(p, f, f.size());
    auto x = RecordingReader::Open(p);
    ASSERT_FALSE(x.ok());
    EXPECT_NE(x.status().message().find("salvage"), std::string::npos) << x.status().message();
    RecordingReaderOptions o;
    o.salvage = true;
    auto y = RecordingReader::Open(p, o);
    ASSERT_TRUE(y.ok()) << y.status().ToString();
    EXPECT_EQ((*y)->summary().num_messages, 2u);
    // Zeros after the last message (a crash after the file grew) are a torn tail.
    std::vector<uint8_t> z(f.begin(), f.begin() + static_cast<std::ptrdiff_t>(all[2].offset));
    z.resize(z.size() + 5000, 0);
    WriteBytes(p, z, z.size());
    auto zz = RecordingReader::Open(p);
    ASSERT_TRUE(zz.ok()) << zz.status().ToString();
    EXPECT_EQ((*zz)->summary().num_messages, 2u);
    EXPECT_EQ((*zz)->summary().ignored_tail_bytes, 5000u);
  }
}

// Every single-byte corruption of a clean file is caught: Open fails, or a
// read fails, or (footer damage) every message is still intact.
TEST(RecordFormat, EverySingleByteCorruptionIsDetected) {
  const std::string dir = test::MakeTempDir("record_flip");
  const std::string p = dir + "/f.hrec";
  const auto msgs = MakeTestStream(4, 30, 3);
  WriteTestRecording(p, msgs);
  const auto bytes = ReadBytes(p);
  size_t open_failed = 0, read_failed = 0, intact = 0;
  for (size_t i = 0; i < bytes.size(); ++i) {
    auto f = bytes;
    f[i] ^= 0x5A;
    WriteBytes(p, f, f.size());
    auto r = RecordingReader::Open(p);
    if (!r.ok()) {
      ++open_failed;
      continue;
    }
    Status error;
    const auto got = ReadAll(**r, &error);
    if (!error.ok()) {
      ++read_failed;
      continue;
    }
    ASSERT_EQ(got.size(), msgs.size()) << "flip at " << i;
    ExpectPrefix(got, msgs);
    ++intact;
  }
  EXPECT_GT(open_failed + read_failed, bytes.size() / 2);
  std::printf("%zu flips: open failed %zu, read failed %zu, all messages intact %zu\n", bytes.size(), open_failed,
              read_failed, intact);
}

}  // namespace
}  // namespace holo::record
