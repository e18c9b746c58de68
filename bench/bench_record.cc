// holoport-bench record --workload S8-QVGA [--json] [--frames N] [--repeats N]
//
// Recording and replay (docs/recording.md) on the synthetic studio's stream
// (ground-truth meshes through G1, 20 ms PCM audio+pose), prepared in memory
// outside the timed code:
//   bytes_per_minute      file size per minute of media (codec g1)
//   write_throughput      MB/s into a file in $TMPDIR (validation on / off), median of repeats
//   write_cpu_ms_per_mb   process CPU per MB written
//   open_ms               opening a closed file (index from the footer) and an
//                         unclosed one (index rebuilt by scanning)
//   seek_ms               Seek + Pump until the key frame is emitted, p50 / p99
//                         over 200 random targets (simulated clock)
//   seek_error_ms         largest |shown key frame − target| over those seeks
//   replay_cpu_ms_per_media_s  pumping the whole file, per second of media
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <random>
#include <string>
#include <vector>

#include "bench.h"
#include "common/clock.h"
#include "server/record/recording_reader.h"
#include "server/record/recording_writer.h"
#include "server/record/replay.h"
#include "server/record/synthetic_stream.h"

namespace holo::bench {
namespace {

double WallMs(const Stopwatch& s) { return s.ElapsedMs(); }

int RunRecordBench(const BenchArgs& args) {
  const int frames = args.frames > 0 ? args.frames : 600;
  const int repeats = std::max(1, args.repeats);
  record::SyntheticStreamOptions so;
  so.workload = args.workload;
  auto stream = record::SyntheticStream::Create(so);
  if (!stream.ok()) {
    std::fprintf(stderr, "bench record: %s\n", stream.status().message().c_str());
    return 1;
  }
  if (!args.json)
    std::fprintf(stderr, "bench record: preparing %d frames of %s (G1 + PCM audio)...\n", frames, args.workload.c_str());
  std::vector<record::StreamMessage> msgs;
  const int64_t end_us = (*stream)->fps() > 0 ? static_cast<int64_t>((frames - 1) * 1e6 / (*stream)->fps() + 0.5) : 0;
  for (;;) {
    record::StreamMessage m;
    if (!(*stream)->Next(&m).ok()) return 1;
    if (m.time_us > end_us) break;
    msgs.push_back(std::move(m));
  }
  uint64_t payload = 0;
  for (const auto& m : msgs) payload += m.frame.size();

  const std::string dir = std::filesystem::temp_directory_path() / ("holo_bench_record_" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/bench.hrec";
  const std::map<std::string, std::string> q = {{"codec", "g1"}};
  auto qual = [&](std::map<std::string, std::string> extra) {
    extra.insert(q.begin(), q.end());
    return extra;
  };

  // Writing.
  for (bool validate : {true, false}) {
    std::vector<double> mbps, cpu_per_mb;
    for (int r = 0; r < repeats; ++r) {
      std::filesystem::remove(path);
      record::RecordingWriterOptions wo;
      wo.validate_payloads = validate;
      wo.source = "bench";
      const double cpu0 = ProcessCpuMs();
      Stopwatch sw;
      auto w = record::RecordingWriter::Create(path, wo);
      if (!w.ok()) return 1;
      for (const auto& m : msgs)
        if (!(*w)->WriteMessage(m.time_us, m.frame).ok()) return 1;
      if (!(*w)->Close().ok()) return 1;
      const double ms = WallMs(sw);
      const double mb = static_cast<double>((*w)->stats().bytes) / 1e6;
      mbps.push_back(mb / (ms / 1e3));
      cpu_per_mb.push_back((ProcessCpuMs() - cpu0) / mb);
    }
    const std::string mode = validate ? "validate" : "no-validate";
    EmitFigure("record", args.workload, "write_throughput", Median(mbps), "MB/s", qual({{"mode", mode}}));
    EmitFigure("record", args.workload, "write_cpu_ms_per_mb", Median(cpu_per_mb), "ms/MB", qual({{"mode", mode}}));
  }
  auto reader = record::RecordingReader::Open(path);
  if (!reader.ok()) return 1;
  const auto& sum = (*reader)->summary();
  EmitFigure("record", args.workload, "bytes_per_minute",
             static_cast<double>(sum.file_bytes) * 60e6 / static_cast<double>(sum.duration_us), "B/min",
             qual({{"media_s", std::to_string(sum.duration_us / 1000000)}}));
  EmitFigure("record", args.workload, "index_bytes_per_minute",
             static_cast<double>(sum.file_bytes - sum.data_end) * 60e6 / static_cast<double>(sum.duration_us), "B/min",
             q);

  // Opening: from the footer, and by scanning a copy without the footer.
  {
    const std::string crashed = dir + "/crashed.hrec";
    std::filesystem::copy_file(path, crashed, std::filesystem::copy_options::overwrite_existing);
    std::filesystem::resize_file(crashed, sum.data_end);
    for (const auto& [mode, p] : {std::pair<std::string, std::string>{"footer", path}, {"scan", crashed}}) {
      std::vector<double> ms;
      for (int r = 0; r < repeats; ++r) {
        Stopwatch sw;
        auto rr = record::RecordingReader::Open(p);
        if (!rr.ok()) return 1;
        ms.push_back(WallMs(sw));
      }
      EmitFigure("record", args.workload, "open_ms", Median(ms), "ms", qual({{"mode", mode}}));
    }
  }

  // Seeking.
  {
    std::shared_ptr<const record::RecordingReader> shared(std::move(*reader));
    SimulatedClock clock(0);
    auto src = record::ReplaySource::Create(shared, &clock);
    if (!src.ok()) return 1;
    std::mt19937 rng(3);
    std::uniform_int_distribution<int64_t> pick(0, shared->summary().duration_us);
    std::vector<double> ms;
    double worst_error_ms = 0;
    for (int i = 0; i < 200; ++i) {
      const int64_t t = pick(rng);
      int64_t shown = -1;
      Stopwatch sw;
      if (!(*src)->Seek(t).ok()) return 1;
      auto n = (*src)->Pump([&](std::shared_ptr<const std::vector<uint8_t>>, protocol::Header h) {
        if (h.type == protocol::MessageType::kMeshFrame && shown < 0) shown = h.capture_time_us;
      });
      ms.push_back(WallMs(sw));
      if (!n.ok() || shown < 0) return 1;
      worst_error_ms = std::max(worst_error_ms, static_cast<double>(t - shown) / 1e3);
      clock.AdvanceUs(10000);
    }
    std::sort(ms.begin(), ms.end());
    EmitFigure("record", args.workload, "seek_ms", Median(ms), "ms", qual({{"stat", "p50"}}));
    EmitFigure("record", args.workload, "seek_ms", ms[static_cast<size_t>(0.99 * (ms.size() - 1))], "ms",
               qual({{"stat", "p99"}}));
    EmitFigure("record", args.workload, "seek_error_ms", worst_error_ms, "ms", qual({{"stat", "max"}}));

    // Replay cost: pump the whole recording at 4× in simulated time.
    record::ReplayOptions ro;
    ro.speed = 4;
    auto all = record::ReplaySource::Create(shared, &clock, ro);
    if (!all.ok()) return 1;
    size_t emitted = 0;
    const double cpu0 = ProcessCpuMs();
    while (!(*all)->state().ended) {
      auto n = (*all)->Pump([&](std::shared_ptr<const std::vector<uint8_t>>, protocol::Header) { ++emitted; });
      if (!n.ok()) return 1;
      clock.AdvanceUs(5000);
    }
    const double cpu = ProcessCpuMs() - cpu0;
    EmitFigure("record", args.workload, "replay_cpu_ms_per_media_s",
               cpu / (static_cast<double>(shared->summary().duration_us) / 1e6), "ms/s",
               qual({{"messages", std::to_string(emitted)}}));
  }
  std::filesystem::remove_all(dir);
  if (!args.json)
    std::fprintf(stderr, "bench record: %zu messages, %.2f MB of protocol frames\n", msgs.size(),
                 static_cast<double>(payload) / 1e6);
  return 0;
}

}  // namespace

HOLO_REGISTER_BENCH("record", "recording write throughput, size per minute, open/seek time, replay cost",
                    RunRecordBench);

}  // namespace holo::bench
