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

#include <map>
#include <memory>
#include <mutex>
#include <thread>

#include <CLI/CLI.hpp>

#include "bench.h"
#include "common/clock.h"
#include "common/log.h"
#include "common/quantile.h"
#include "net/session_server.h"
#include "net/site_client.h"
#include "server/record/recording_reader.h"
#include "server/record/recording_sink.h"
#include "server/record/recording_writer.h"
#include "server/record/replay.h"
#include "server/record/replay_net.h"
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
    spdlog::error("bench record: {}", stream.status().message());
    return 1;
  }
  if (!args.json) spdlog::info("bench record: preparing {} frames of {} (G1 + PCM audio)...", frames, args.workload);
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
  const std::map<std::string, std::string> q = {{"codec", "g1"}, {"content", "truth"}};
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
    spdlog::info("bench record: {} messages, {:.2f} MB of protocol frames", msgs.size(),
                 static_cast<double>(payload) / 1e6);
  return 0;
}


// holoport-bench replaynet --workload S8-QVGA [--frames N] [--viewers N] [--json]
//
// Living memories over loopback (docs/recording.md §5):
//  * replay: a recording of the synthetic stream (G1 + PCM audio) served by
//    ReplayServer (holoport-server --replay --listen) at 1× to N viewers
//    (SiteClient, no decoding, one shared io thread):
//      replay_latency_ms      mesh frame received by a viewer − its due time on the schedule, p50 / p99
//      replay_emit_late_ms    mesh frame handed to the fan-out − due time, p50 / p99
//      replay_delivered_fraction  mesh frames received / emitted, the worst viewer
//      replay_server_cpu_pct_per_viewer  io threads + pump thread CPU over wall, per viewer (% of one core)
//  * live recording: the same stream published in real time by a site
//    (session server + RecordedPublisher) and recorded by a recorder
//    (SiteClient role recorder → RecordingSink → RecordingWriter, as
//    holoport-record --connect):
//      live_record_bytes_per_minute   file bytes per minute of media
//      live_record_cpu_pct            recorder io thread CPU (receive + write) over wall, % of one core
//      live_record_messages           messages recorded / published
constexpr int kReplayNetDefaultViewers = 10;

int RunReplayNetBench(const BenchArgs& args, int viewers_option) {
  const int frames = args.frames > 0 ? args.frames : 300;
  const int viewers = std::max(1, viewers_option);
  record::SyntheticStreamOptions so;
  so.workload = args.workload;
  auto stream = record::SyntheticStream::Create(so);
  if (!stream.ok()) {
    spdlog::error("bench replaynet: {}", stream.status().message());
    return 1;
  }
  if (!args.json) spdlog::info("bench replaynet: preparing {} frames of {} (G1 + PCM audio)...", frames, args.workload);
  std::vector<record::StreamMessage> msgs;
  const int64_t end_us = static_cast<int64_t>((frames - 1) * 1e6 / (*stream)->fps() + 0.5);
  for (;;) {
    record::StreamMessage m;
    if (!(*stream)->Next(&m).ok()) return 1;
    if (m.time_us > end_us) break;
    msgs.push_back(std::move(m));
  }
  const std::string dir = std::filesystem::temp_directory_path() / ("holo_bench_replaynet_" + std::to_string(getpid()));
  std::filesystem::create_directories(dir);
  const std::string path = dir + "/talk.hrec";
  {
    record::RecordingWriterOptions wo;
    wo.source = "synthetic:" + args.workload;
    auto w = record::RecordingWriter::Create(path, wo, true);
    if (!w.ok()) return 1;
    for (const auto& m : msgs)
      if (!(*w)->WriteMessage(m.time_us, m.frame).ok()) return 1;
    if (!(*w)->Close().ok()) return 1;
  }
  auto qual = [&](std::map<std::string, std::string> q) {
    q["viewers"] = std::to_string(viewers);
    q["content"] = "truth";
    return q;
  };
  RealClock& clock = RealClock::Instance();
  net::ServerConfig cfg;
  cfg.host = "127.0.0.1";
  cfg.publisher_token = "bench-pub";
  cfg.viewer_token = "bench-view";
  cfg.threads = 2;

  // --- replay to N viewers ---
  {
    auto r = record::RecordingReader::Open(path);
    if (!r.ok()) return 1;
    std::shared_ptr<const record::RecordingReader> reader(std::move(*r));
    std::mutex mu;
    std::map<uint32_t, int64_t> due_of;  // mesh sequence → due (clock µs)
    std::vector<double> late_ms;
    double pump_cpu_ms = 0;
    record::ReplayServerOptions o;
    o.net = cfg;
    o.replay.start_paused = true;
    o.log = [](const std::string&) {};
    o.on_emit = [&](const protocol::Header& h, int64_t due, int64_t emitted) {
      if (h.type != protocol::MessageType::kMeshFrame) return;
      std::lock_guard<std::mutex> l(mu);
      due_of[h.sequence] = due;
      late_ms.push_back(static_cast<double>(emitted - due) * 1e-3);
      pump_cpu_ms = ThreadCpuTimeMs();  // the pump thread's CPU so far
    };
    auto rs = record::ReplayServer::Start(reader, &clock, o);
    if (!rs.ok()) {
      spdlog::error("bench replaynet: {}", rs.status().message());
      return 1;
    }
    net::NetContext ctx(1);
    std::vector<double> latency_ms;
    std::vector<uint64_t> received(static_cast<size_t>(viewers), 0);
    std::vector<std::unique_ptr<net::SiteClient>> clients;
    for (int v = 0; v < viewers; ++v) {
      net::ClientOptions co;
      co.port = (*rs)->port();
      co.token = cfg.viewer_token;
      co.decode = false;
      co.reconnect = false;
      net::ClientCallbacks cb;
      cb.on_raw = [&, v](const net::RawMessage& m) {
        if (m.header.type != protocol::MessageType::kMeshFrame || m.header.sequence == 0) return;
        const int64_t now = clock.NowUs();
        std::lock_guard<std::mutex> l(mu);
        received[static_cast<size_t>(v)] += 1;
        auto it = due_of.find(m.header.sequence);
        if (it != due_of.end()) latency_ms.push_back(static_cast<double>(now - it->second) * 1e-3);
      };
      auto c = net::SiteClient::Start(co, cb, &ctx);
      if (!c.ok() || !(*c)->WaitConnected(10)) {
        spdlog::error("bench replaynet: viewer {} did not connect", v);
        return 1;
      }
      clients.push_back(std::move(*c));
    }
    while ((*rs)->server().num_subscribed(net::kContentGeometry) < static_cast<size_t>(viewers))
      clock.SleepUntilUs(clock.NowUs() + 5000);
    clock.SleepUntilUs(clock.NowUs() + 200000);
    {
      std::lock_guard<std::mutex> l(mu);
      late_ms.clear();
    }
    const double io0 = (*rs)->server().IoCpuMs();
    double pump0;
    {
      std::lock_guard<std::mutex> l(mu);
      pump0 = pump_cpu_ms;
    }
    const int64_t t0 = clock.NowUs();
    (*rs)->source().Resume();
    while (!(*rs)->source().state().ended) clock.SleepUntilUs(clock.NowUs() + 20000);
    clock.SleepUntilUs(clock.NowUs() + 300000);  // let the last frames arrive
    const double wall_ms = static_cast<double>(clock.NowUs() - t0) * 1e-3;
    const double io_ms = (*rs)->server().IoCpuMs() - io0;
    for (auto& c : clients) c->Stop();
    std::lock_guard<std::mutex> l(mu);
    const double cpu_ms = io_ms + (pump_cpu_ms - pump0);
    const uint64_t expected = static_cast<uint64_t>(frames - 1);
    const uint64_t worst = *std::min_element(received.begin(), received.end());
    EmitFigure("replaynet", args.workload, "replay_latency_ms", Quantile(latency_ms, 0.5), "ms", qual({{"stat", "p50"}}));
    EmitFigure("replaynet", args.workload, "replay_latency_ms", Quantile(latency_ms, 0.99), "ms", qual({{"stat", "p99"}}));
    EmitFigure("replaynet", args.workload, "replay_emit_late_ms", Quantile(late_ms, 0.5), "ms", qual({{"stat", "p50"}}));
    EmitFigure("replaynet", args.workload, "replay_emit_late_ms", Quantile(late_ms, 0.99), "ms", qual({{"stat", "p99"}}));
    EmitFigure("replaynet", args.workload, "replay_delivered_fraction",
               static_cast<double>(worst) / static_cast<double>(expected), "1", qual({{"class", "worst_viewer"}}));
    EmitFigure("replaynet", args.workload, "replay_server_cpu_pct_per_viewer",
               100.0 * cpu_ms / wall_ms / viewers, "%", qual({{"frames", std::to_string(frames)}}));
  }

  // --- live recording ---
  {
    auto server = net::Server::Start(cfg, net::ServerHooks{[](const std::string&) {}, nullptr, nullptr});
    if (!server.ok()) return 1;
    record::RecordedPublisher publisher(server->get());
    if (!publisher.Publish(msgs[0].frame, *protocol::DecodeHeader(msgs[0].frame.data(), msgs[0].frame.size())).ok())
      return 1;
    const std::string rec_path = dir + "/live.hrec";
    record::RecordingWriterOptions wo;
    wo.source = "bench-live";
    auto writer = record::RecordingWriter::Create(rec_path, wo, true);
    if (!writer.ok()) return 1;
    record::RecordingSink sink(writer->get());
    std::mutex mu;
    net::NetContext ctx(1);
    net::ClientOptions co;
    co.port = (*server)->port();
    co.token = cfg.viewer_token;
    co.role = protocol::Role::kRecorder;
    co.decode = false;
    co.reconnect = false;
    net::ClientCallbacks cb;
    cb.on_raw = [&](const net::RawMessage& m) {
      const int64_t now = clock.NowUs();
      std::lock_guard<std::mutex> l(mu);
      (void)sink.AddFrame(protocol::Frame{m.header, m.payload}, now);
    };
    auto c = net::SiteClient::Start(co, cb, &ctx);
    if (!c.ok() || !(*c)->WaitConnected(10)) return 1;
    while ((*server)->num_subscribed(net::kContentGeometry) < 1) clock.SleepUntilUs(clock.NowUs() + 5000);
    const double cpu0 = ctx.CpuMs();
    const int64_t t0 = clock.NowUs();
    for (size_t i = 1; i < msgs.size(); ++i) {
      clock.SleepUntilUs(t0 + msgs[i].time_us);
      if (!publisher.Publish(msgs[i].frame, *protocol::DecodeHeader(msgs[i].frame.data(), msgs[i].frame.size())).ok())
        return 1;
      publisher.Flush();
    }
    clock.SleepUntilUs(clock.NowUs() + 300000);
    (*c)->Stop();
    const double wall_ms = static_cast<double>(clock.NowUs() - t0) * 1e-3;
    const double cpu_ms = ctx.CpuMs() - cpu0;
    if (!(*writer)->Close().ok()) return 1;
    const auto& ws = (*writer)->stats();
    EmitFigure("replaynet", args.workload, "live_record_bytes_per_minute",
               static_cast<double>(ws.bytes) * 60.0 / (static_cast<double>(ws.duration_us) * 1e-6) / 1e6, "MB/min",
               {{"codec", "g1"}, {"audio", "pcm16"}});
    EmitFigure("replaynet", args.workload, "live_record_cpu_pct", 100.0 * cpu_ms / wall_ms, "%",
               {{"stage", "recorder_io_thread"}});
    EmitFigure("replaynet", args.workload, "live_record_messages", static_cast<double>(ws.messages), "messages",
               {{"published", std::to_string(msgs.size())}});
  }
  std::filesystem::remove_all(dir);
  return 0;
}

}  // namespace

BenchFn SetupReplayNet(CLI::App& app) {
  DropCommonOptions(app, {"--repeats"});  // this benchmark does not read them
  auto viewers = std::make_shared<int>(kReplayNetDefaultViewers);
  app.add_option("--viewers", *viewers, "viewers of the replay")->capture_default_str()->check(CLI::PositiveNumber);
  return [viewers](const BenchArgs& args) { return RunReplayNetBench(args, *viewers); };
}

HOLO_REGISTER_BENCH_OPTIONS("replaynet",
                            "replay served over loopback to N viewers (latency vs schedule, CPU) and recording a live site",
                            SetupReplayNet);
HOLO_REGISTER_BENCH_OPTIONS("record", "recording write throughput, size per minute, open/seek time, replay cost",
                            NoOptions(RunRecordBench));

}  // namespace holo::bench
