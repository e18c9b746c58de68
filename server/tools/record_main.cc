// holoport-record: writes a recording (living memory) of a protocol stream,
// validates and describes recordings (--info), and cuts them into segments for
// an HTTP cache (--cut). docs/recording.md describes the format and the
// commands.
#include <time.h>

#include <algorithm>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "common/clock.h"
#include "common/log.h"
#include "net/server_config.h"
#include "net/site_client.h"
#include "server/record/inspect.h"
#include "server/record/live_packager.h"
#include "server/record/recording_reader.h"
#include "server/record/recording_sink.h"
#include "server/record/recording_writer.h"
#include "server/record/segments.h"
#include "server/record/synthetic_stream.h"

namespace {

volatile std::sig_atomic_t g_stop = 0;

double ProcessCpuMs() {
  timespec ts{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &ts);
  return static_cast<double>(ts.tv_sec) * 1e3 + static_cast<double>(ts.tv_nsec) * 1e-6;
}
void OnSignal(int) { g_stop = 1; }

int Fail(const holo::Status& s) {
  spdlog::error("holoport-record: {}", s.message());
  return 1;
}

// The exit code for how a recording ended, `end` being the writer's (or the
// sink's) error or OK: OK closes the recording, 0 (a failing close becomes
// *end, 4); kOutOfRange the size limit, 3; kUnavailable disk full or a write
// failure, 4; anything else 1, the recording left open for the caller.
int EndCode(holo::record::RecordingWriter* writer, holo::Status* end) {
  if (end->ok()) {
    holo::Status c = writer->Close();
    if (c.ok()) return 0;
    *end = c;
    return 4;
  }
  if (end->code() == holo::StatusCode::kOutOfRange) return 3;
  if (end->code() == holo::StatusCode::kUnavailable) return 4;
  return 1;
}

// Exit codes: 0 done, 1 error (nothing or a damaged file), 3 size limit
// reached and 4 disk full / write failure (the recording is valid up to there).
int Record(const std::string& out, const std::string& source_spec, double duration_s, uint64_t max_bytes,
           const std::string& codec, double step_mm, bool audio, bool realtime, bool overwrite, double sync_mb,
           bool quiet) {
  holo::record::SyntheticStreamOptions so;
  if (source_spec == "synthetic") {
    so.workload = "S8-QVGA";
  } else if (source_spec.rfind("synthetic:", 0) == 0) {
    so.workload = source_spec.substr(10);
  } else {
    return Fail(holo::InvalidArgument("--source must be synthetic[:WORKLOAD], got '" + source_spec +
                                      "' (to record a live site, use --connect HOST:PORT --token T)"));
  }
  if (codec == "g1") {
    so.geometry.codec = holo::protocol::GeometryCodec::kG1;
  } else if (codec == "g0") {
    so.geometry.codec = holo::protocol::GeometryCodec::kG0;
  } else {
    return Fail(holo::InvalidArgument("--codec must be g1 or g0, got '" + codec + "'"));
  }
  so.geometry.position_step_m = static_cast<float>(step_mm * 1e-3);
  so.audio = audio;
  if (!(duration_s >= 0)) return Fail(holo::InvalidArgument("--duration must be ≥ 0"));
  auto stream = holo::record::SyntheticStream::Create(so);
  if (!stream.ok()) return Fail(stream.status());

  holo::record::RecordingWriterOptions wo;
  wo.max_bytes = max_bytes;
  wo.source = "synthetic:" + so.workload;
  wo.sync_every_bytes = static_cast<uint64_t>(sync_mb * 1e6);
  auto writer = holo::record::RecordingWriter::Create(out, wo, overwrite);
  if (!writer.ok()) return Fail(writer.status());

  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  const int64_t limit_us = duration_s > 0 ? static_cast<int64_t>(duration_s * 1e6) : INT64_MAX;
  if (!quiet)
    spdlog::info("holoport-record: {} → {} ({}{}, {}){}", wo.source, out, codec, audio ? " + PCM audio" : "",
                 duration_s > 0 ? holo::record::FormatSeconds(limit_us).c_str() : "until stopped",
                 max_bytes ? (", limit " + std::to_string(max_bytes) + " bytes").c_str() : "");
  holo::RealClock& clock = holo::RealClock::Instance();
  const int64_t start = clock.NowUs();
  int64_t next_progress = start + 1000000;
  holo::record::StreamMessage m;
  holo::Status end;
  double write_ms = 0;
  while (!g_stop) {
    holo::Status s = (*stream)->Next(&m);
    if (!s.ok()) return Fail(s);
    if (m.time_us > limit_us) break;
    if (realtime) clock.SleepUntilUs(start + m.time_us);
    holo::Stopwatch sw;
    end = (*writer)->WriteMessage(m.time_us, m.frame);
    write_ms += sw.ElapsedMs();
    if (!end.ok()) break;
    const int64_t now = clock.NowUs();
    if (!quiet && now >= next_progress) {
      const auto& st = (*writer)->stats();
      spdlog::info("  {} recorded, {} messages, {:.2f} MB", holo::record::FormatSeconds(st.duration_us), st.messages,
                   static_cast<double>(st.bytes) / 1e6);
      next_progress = now + 1000000;
    }
  }
  const int code = EndCode(writer->get(), &end);
  if (code == 1) return Fail(end);  // a message the writer refused (should not happen with our own source)
  const auto& st = (*writer)->stats();
  const double wall_s = static_cast<double>(clock.NowUs() - start) * 1e-6;
  if (code != 0) spdlog::error("holoport-record: {}", end.message());
  if (g_stop && !quiet) spdlog::info("holoport-record: stopped by signal; recording closed");
  if (!quiet)
    spdlog::info(
        "holoport-record: {}: {} messages ({} key frames), {}, {:.2f} MB in {:.1f} s wall; "
        "{:.2f} MB per minute of media; writing took {:.1f} ms ({:.0f} MB/s)",
        out, st.messages, st.key_frames, holo::record::FormatSeconds(st.duration_us),
        static_cast<double>(st.bytes) / 1e6, wall_s,
        st.duration_us > 0 ? static_cast<double>(st.bytes) * 60.0 / static_cast<double>(st.duration_us) : 0.0, write_ms,
        write_ms > 0 ? static_cast<double>(st.bytes) / 1e3 / write_ms : 0.0);
  return code;
}

// Client options of a recorder connection to a live site (role recorder,
// raw messages, everything subscribed); the token falls back to env
// HOLO_VIEWER_TOKEN. Shared by --connect and --live-dir.
holo::StatusOr<holo::net::ClientOptions> RecorderClientOptions(const std::string& connect, std::string token,
                                                               const std::string& name, bool tls,
                                                               const std::string& ca_file, double connect_timeout_s) {
  holo::net::ClientOptions co;
  HOLO_RETURN_IF_ERROR(holo::net::ParseHostPort(connect, &co.host, &co.port).WithContext("--connect"));
  if (co.host == "0.0.0.0") co.host = "127.0.0.1";
  if (token.empty() && std::getenv("HOLO_VIEWER_TOKEN")) token = std::getenv("HOLO_VIEWER_TOKEN");
  if (token.empty())
    return holo::InvalidArgument("--connect needs the site's viewer token: --token or env HOLO_VIEWER_TOKEN");
  co.role = holo::protocol::Role::kRecorder;
  co.token = token;
  co.name = name;
  co.decode = false;
  // Regions too when the site announces them (recordings keep them; live
  // segments do not: RecordLiveDir subscribes without them).
  co.subscribe = holo::net::kSubscribeAll | holo::net::kSubscribeRegions;
  co.tls.enabled = tls;
  co.tls.ca_file = ca_file;
  co.connect_timeout_s = connect_timeout_s;
  return co;
}

// Records a live site: subscribes like a viewer (role recorder) through
// SiteClient and writes every message it receives (raw, exactly as sent)
// through RecordingSink. Exit codes as Record().
int RecordLive(const std::string& out, const std::string& connect, std::string token, double duration_s,
               uint64_t max_bytes, bool overwrite, double sync_mb, bool tls, const std::string& ca_file,
               double connect_timeout_s, bool quiet) {
  auto options = RecorderClientOptions(connect, token, "holoport-record", tls, ca_file, connect_timeout_s);
  if (!options.ok()) return Fail(options.status());
  if (!(duration_s >= 0)) return Fail(holo::InvalidArgument("--duration must be ≥ 0"));
  holo::net::ClientOptions co = *options;
  holo::Status check = co.Check();
  if (!check.ok()) return Fail(check);

  holo::record::RecordingWriterOptions wo;
  wo.max_bytes = max_bytes;
  wo.source = ("site:" + connect).substr(0, 31);
  wo.sync_every_bytes = static_cast<uint64_t>(sync_mb * 1e6);
  auto writer = holo::record::RecordingWriter::Create(out, wo, overwrite);
  if (!writer.ok()) return Fail(writer.status());
  holo::record::RecordingSink sink(writer->get());

  holo::RealClock& clock = holo::RealClock::Instance();
  const int64_t limit_us = duration_s > 0 ? static_cast<int64_t>(duration_s * 1e6) : INT64_MAX;
  std::mutex mu;
  bool done = false;     // duration reached or the recording ended (under mu)
  holo::Status end;      // the writer's / sink's error (under mu)
  double write_ms = 0;   // under mu
  holo::net::ClientCallbacks cb;
  cb.on_raw = [&](const holo::net::RawMessage& m) {
    const int64_t now = clock.NowUs();
    std::lock_guard<std::mutex> l(mu);
    if (done) return;
    holo::protocol::Frame f{m.header, m.payload};
    holo::Stopwatch sw;
    holo::Status s = sink.AddFrame(f, now);
    write_ms += sw.ElapsedMs();
    if (!s.ok()) {
      end = s;
      done = true;
    } else if ((*writer)->stats().duration_us >= limit_us) {
      done = true;
    }
  };
  cb.on_state = [&](holo::net::ClientState state, const holo::Status& why) {
    if (quiet) return;
    if (state == holo::net::ClientState::kConnected)
      spdlog::info("holoport-record: connected to {}; recording", connect);
    else if (state == holo::net::ClientState::kBackoff)
      spdlog::warn("holoport-record: {} (retrying): {}", connect, why.message());
  };
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  if (!quiet)
    spdlog::info("holoport-record: {} → {} ({}{})", connect, out,
                 duration_s > 0 ? holo::record::FormatSeconds(limit_us).c_str() : "until stopped",
                 max_bytes ? (", limit " + std::to_string(max_bytes) + " bytes").c_str() : "");
  const int64_t start = clock.NowUs();
  const double cpu_start = ProcessCpuMs();
  auto client = holo::net::SiteClient::Start(co, cb);
  if (!client.ok()) return Fail(client.status());
  int64_t next_progress = start + 1000000;
  bool refused = false;
  while (!g_stop) {
    clock.SleepUntilUs(clock.NowUs() + 50000);
    {
      std::lock_guard<std::mutex> l(mu);
      if (done) break;
    }
    if ((*client)->state() == holo::net::ClientState::kRefused) {
      refused = true;
      break;
    }
    const int64_t now = clock.NowUs();
    if (!quiet && now >= next_progress) {
      std::lock_guard<std::mutex> l(mu);
      const auto& ws = (*writer)->stats();
      spdlog::info(
          "  {} recorded, {} messages, {:.2f} MB, {:.2f} MB/min", holo::record::FormatSeconds(ws.duration_us),
          ws.messages, static_cast<double>(ws.bytes) / 1e6,
          ws.duration_us > 0 ? static_cast<double>(ws.bytes) * 60.0 / static_cast<double>(ws.duration_us) : 0.0);
      next_progress = now + 1000000;
    }
  }
  (*client)->Stop();  // no callback runs after this
  const holo::Status client_status = (*client)->status();
  int code = EndCode(writer->get(), &end);
  if (code == 1) (void)(*writer)->Close();  // a malformed stream: keep what came before, closed
  if (code != 0) spdlog::error("holoport-record: {}", end.message());
  if (refused) {
    spdlog::error("holoport-record: the site refused the recorder: {}", client_status.message());
    if (code == 0) code = 1;
    if ((*writer)->stats().messages == 0) {
      std::remove(out.c_str());  // nothing recorded: do not leave an empty recording behind
      return code;
    }
  }
  const auto& ws = (*writer)->stats();
  const auto& ss = sink.stats();
  const double wall_s = static_cast<double>(clock.NowUs() - start) * 1e-6;
  const double cpu_ms = ProcessCpuMs() - cpu_start;
  if (g_stop && !quiet) spdlog::info("holoport-record: stopped by signal; recording closed");
  if (!quiet)
    spdlog::info(
        "holoport-record: {}: {} messages ({} key frames; {} session messages not recorded), {}, "
        "{:.2f} MB in {:.1f} s wall; {:.2f} MB per minute of media; CPU {:.0f} ms ({:.1f}% of one core), "
        "writing {:.1f} ms",
        out, ws.messages, ws.key_frames, ss.ignored_types, holo::record::FormatSeconds(ws.duration_us),
        static_cast<double>(ws.bytes) / 1e6, wall_s,
        ws.duration_us > 0 ? static_cast<double>(ws.bytes) * 60.0 / static_cast<double>(ws.duration_us) : 0.0, cpu_ms,
        wall_s > 0 ? cpu_ms / (wall_s * 10.0) : 0.0, write_ms);
  return code;
}

// Packages a live stream for HTTP caches (docs/broadcast.md): a live site
// (--connect, as a viewer-side recorder) or the synthetic studio paced in real
// time (--source synthetic). Parts and segments appear in `o.dir` as they
// complete; a site disconnect closes the segment (the next one is a
// discontinuity). Runs until --duration, Ctrl-C or a write failure.
int PackageLive(holo::record::LivePackagerOptions o, const std::string& connect, const std::string& source_spec,
                std::string token, double duration_s, bool tls, const std::string& ca_file, double connect_timeout_s,
                bool quiet) {
  holo::RealClock& clock = holo::RealClock::Instance();
  auto wall_us = [] {
    timespec ts{};
    clock_gettime(CLOCK_REALTIME, &ts);
    return static_cast<int64_t>(ts.tv_sec) * 1000000 + ts.tv_nsec / 1000;
  };
  if (!(duration_s >= 0)) return Fail(holo::InvalidArgument("--duration must be ≥ 0"));
  o.source = (connect.empty() ? source_spec : "site:" + connect).substr(0, 31);
  auto packager = holo::record::LivePackager::Open(o, wall_us());
  if (!packager.ok()) return Fail(packager.status());
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  const int64_t start = clock.NowUs();
  const int64_t end = duration_s > 0 ? start + static_cast<int64_t>(duration_s * 1e6) : INT64_MAX;
  std::mutex mu;
  holo::Status failed;  // a write failure ends the broadcast (under mu)
  std::vector<uint8_t> frame;
  auto add = [&](const holo::protocol::Header& h, std::span<const uint8_t> payload, int64_t at) {
    frame.resize(holo::protocol::kHeaderSize + payload.size());
    holo::protocol::Header hh = h;
    hh.payload_length = static_cast<uint32_t>(payload.size());
    holo::protocol::EncodeHeader(hh, frame.data());
    std::copy(payload.begin(), payload.end(), frame.begin() + holo::protocol::kHeaderSize);
    holo::Status s = (*packager)->AddMessage(frame, at);
    if (s.code() == holo::StatusCode::kInvalidArgument) {
      if (!quiet) spdlog::warn("holoport-record: skipped a message: {}", s.message());
    } else if (!s.ok() && failed.ok()) {
      failed = s;
    }
  };
  if (!quiet)
    spdlog::info("holoport-record: {} → {} (segments {:.2f} s, parts {} ms)", o.source, o.dir,
                 static_cast<double>(o.segment_us) * 1e-6, o.part_us / 1000);
  std::unique_ptr<holo::net::SiteClient> client;
  std::unique_ptr<holo::record::SyntheticStream> synthetic;
  if (!connect.empty()) {
    auto options = RecorderClientOptions(connect, token, "holoport-record --live-dir", tls, ca_file, connect_timeout_s);
    if (!options.ok()) return Fail(options.status());
    holo::net::ClientOptions co = *options;
    // Segments start at a whole-frame key frame (MeshFrame KEY_FRAME: the
    // geometry and every pod's colour decode alone). Intra-only colour
    // (C0/C1) makes every frame one; with V1 video the packager asks the
    // site for one when a segment is due (LivePackager::WantsKeyFrame).
    co.capabilities.color = {holo::protocol::ColorCodec::kC1, holo::protocol::ColorCodec::kC0,
                             holo::protocol::ColorCodec::kV1};
    // Every geometry codec a site publishes: the browser viewer decodes all
    // three (web/src/geometry.js), G3 since it was ported.
    co.capabilities.geometry = {holo::protocol::GeometryCodec::kG1, holo::protocol::GeometryCodec::kG0,
                                holo::protocol::GeometryCodec::kG3};
    co.subscribe = holo::net::kSubscribeAll;  // live segments carry no Regions (docs/regions.md)
    holo::Status check = co.Check();
    if (!check.ok()) return Fail(check);
    holo::net::ClientCallbacks cb;
    cb.on_raw = [&](const holo::net::RawMessage& m) {
      std::lock_guard<std::mutex> l(mu);
      add(m.header, m.payload, m.received_us);
    };
    cb.on_state = [&](holo::net::ClientState state, const holo::Status& why) {
      if (state == holo::net::ClientState::kBackoff || state == holo::net::ClientState::kRefused) {
        std::lock_guard<std::mutex> l(mu);
        holo::Status s = (*packager)->Discontinuity(wall_us());
        if (!s.ok() && failed.ok()) failed = s;
      }
      if (quiet) return;
      if (state == holo::net::ClientState::kConnected)
        spdlog::info("holoport-record: connected to {}; packaging", connect);
      else if (state == holo::net::ClientState::kBackoff)
        spdlog::warn("holoport-record: {} (retrying): {}", connect, why.message());
    };
    auto c = holo::net::SiteClient::Start(co, cb);
    if (!c.ok()) return Fail(c.status());
    client = std::move(*c);
  } else {
    holo::record::SyntheticStreamOptions so;
    if (source_spec == "synthetic") {
      so.workload = "S8-QVGA";
    } else if (source_spec.rfind("synthetic:", 0) == 0) {
      so.workload = source_spec.substr(10);
    } else {
      return Fail(holo::InvalidArgument("--live-dir needs --connect HOST:PORT or --source synthetic[:WORKLOAD], got '" +
                                        source_spec + "'"));
    }
    auto s = holo::record::SyntheticStream::Create(so);
    if (!s.ok()) return Fail(s.status());
    synthetic = std::move(*s);
  }
  const int64_t wall_start = wall_us();
  holo::record::StreamMessage sm;
  bool have_sm = false;
  bool refused = false;
  while (!g_stop && clock.NowUs() < end) {
    if (synthetic) {
      // Everything due now, then sleep until the next message or tick.
      while (true) {
        if (!have_sm) {
          holo::Status s = synthetic->Next(&sm);
          if (!s.ok()) return Fail(s);
          have_sm = true;
        }
        if (wall_start + sm.time_us > wall_us()) break;
        auto h = holo::protocol::DecodeHeader(sm.frame.data(), sm.frame.size(), holo::protocol::Limits{});
        if (!h.ok()) return Fail(h.status());
        std::lock_guard<std::mutex> l(mu);
        add(*h, std::span<const uint8_t>(sm.frame).subspan(holo::protocol::kHeaderSize), wall_us());
        have_sm = false;
      }
    }
    clock.SleepUntilUs(clock.NowUs() + 5000);
    std::lock_guard<std::mutex> l(mu);
    holo::Status s = (*packager)->Tick(wall_us());
    if (!s.ok() && failed.ok()) failed = s;
    if (client && client->state() == holo::net::ClientState::kConnected && (*packager)->WantsKeyFrame(wall_us())) {
      holo::protocol::Control c;
      c.command = holo::protocol::ControlCommand::kRequestKeyFrame;
      client->SendControl(c);
    }
    if (!failed.ok()) break;
    if (client && client->state() == holo::net::ClientState::kRefused) {
      refused = true;
      break;
    }
  }
  if (client) client->Stop();  // no callback runs after this
  std::lock_guard<std::mutex> l(mu);
  if (!failed.ok()) return Fail(failed);
  holo::Status f = (*packager)->Finish(wall_us());
  if (!f.ok()) return Fail(f);
  const auto& st = (*packager)->stats();
  if (!quiet)
    spdlog::info(
        "holoport-record: {} messages in {} parts, {} segments closed ({} pruned), {} dropped "
        "before a key frame, {} rejected, {} not broadcast (session messages), {} key frames asked for; next segment {}",
        st.messages, st.parts, st.segments, st.pruned_segments, st.dropped_before_key, st.rejected,
        st.ignored_types, st.keyframe_requests, (*packager)->next_segment());
  if (refused) {
    spdlog::error("holoport-record: the site refused the packager: {}", client->status().message());
    return 1;
  }
  return 0;
}

int Info(const std::string& path, bool deep, bool json, bool salvage) {
  holo::record::RecordingReaderOptions o;
  o.salvage = salvage;
  auto reader = holo::record::RecordingReader::Open(path, o);
  if (!reader.ok()) return Fail(reader.status());
  auto in = holo::record::InspectRecording(**reader, deep);
  if (!in.ok()) return Fail(in.status());
  if (json) {
    std::printf("%s\n", holo::record::InspectionJson(**reader, *in).c_str());
  } else {
    std::printf("%s", holo::record::InspectionText(**reader, *in).c_str());
  }
  return 0;
}

int Cut(const std::string& path, double segment_s, const std::string& dir, bool quiet) {
  auto reader = holo::record::RecordingReader::Open(path);
  if (!reader.ok()) return Fail(reader.status());
  auto segs = holo::record::CutSegments(**reader, static_cast<int64_t>(segment_s * 1e6), dir);
  if (!segs.ok()) return Fail(segs.status());
  if (!quiet)
    for (const auto& s : *segs)
      spdlog::info("  {}: {} .. {}, {} messages, {} bytes", s.file, holo::record::FormatSeconds(s.start_us),
                   holo::record::FormatSeconds(s.end_us), s.messages, s.bytes);
  spdlog::info("holoport-record: {} segments and manifest.json in {}", segs->size(), dir);
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{
      "holoport-record: records a Holoport protocol stream into a crash-safe, seekable file (a \"living\n"
      "memory\") — a live site (--connect HOST:PORT --token T) or the synthetic studio (--source) —,\n"
      "validates and describes recordings, and cuts them into segments for an HTTP cache.\n"
      "Replay a recording to viewers with: holoport-server --replay FILE --listen HOST:PORT --viewer-token T\n"
      "[--speed S] [--loop].\n"
      "Exit codes: 0 done; 1 error; 3 size limit reached, 4 disk full (in both cases the file holds\n"
      "everything recorded before and is closed with an index when possible)."};
  holo::AddLogLevelOption(app);
  std::string out, source = "synthetic:S8-QVGA", info_path, cut_path, out_dir, codec = "g1";
  double duration = 10, step_mm = 1.0, sync_mb = 8, segment_s = 2;
  uint64_t max_bytes = 0;
  bool no_audio = false, realtime = false, overwrite = false, deep = false, json = false, salvage = false,
       quiet = false;
  auto* out_opt = app.add_option("-o,--out", out, "record into this file (must not exist unless --overwrite)");
  app.add_option("--source", source,
                 "what to record: synthetic[:WORKLOAD] (the studio's ground-truth meshes through the geometry "
                 "codec, plus 20 ms PCM audio+pose frames)")
      ->capture_default_str();
  app.add_option("--duration", duration,
                 "seconds of media to record (0: until the size limit or Ctrl-C; with --connect default 0)")
      ->capture_default_str();
  app.add_option("--max-bytes", max_bytes, "size limit of the file, index included (0: none); K/M/G suffixes")
      ->transform(CLI::AsSizeValue(false));
  app.add_option("--codec", codec, "geometry codec: g1 or g0")->capture_default_str();
  app.add_option("--position-step-mm", step_mm, "G1 position quantization, mm")->capture_default_str();
  app.add_flag("--no-audio", no_audio, "no audio+pose frames");
  app.add_flag("--realtime", realtime, "pace the synthetic source like a live site (30 fps)");
  app.add_flag("--overwrite", overwrite, "replace an existing --out file");
  app.add_option("--sync-mb", sync_mb, "fdatasync after this many MB (0: only at the end)")->capture_default_str();
  auto* info_opt = app.add_option("--info", info_path, "validate FILE and print duration, frames, size, index");
  app.add_flag("--deep", deep, "--info: also decode every geometry blob");
  app.add_flag("--json", json, "--info: one JSON object instead of text");
  app.add_flag("--salvage", salvage, "--info: read a damaged, unclosed file up to the damage");
  auto* cut_opt = app.add_option("--cut", cut_path, "cut FILE into independently playable segments (needs --out-dir)");
  app.add_option("--out-dir", out_dir, "--cut: directory for seg_NNNNN.hrec and manifest.json");
  app.add_option("--segment-seconds", segment_s, "--cut: target segment length")->capture_default_str();
  std::string connect, token, ca_file;
  bool tls = false;
  double connect_timeout_s = 5;
  app.add_option("--connect", connect,
                 "record a live site: connect to HOST:PORT as a recorder (needs --token) and write every message "
                 "as received; stops after --duration, at --max-bytes, or on Ctrl-C (the file is closed with its "
                 "index)");
  app.add_option("--token", token, "--connect: the site's viewer token (default: env HOLO_VIEWER_TOKEN)");
  app.add_flag("--tls", tls, "--connect: TLS");
  app.add_option("--ca-file", ca_file, "--connect --tls: trusted certificates (PEM)");
  app.add_option("--connect-timeout", connect_timeout_s, "--connect: seconds for connect + handshake per attempt")
      ->capture_default_str();
  std::string live_dir;
  double part_ms = 250;
  int window = 10;
  int cache_bucket_ms = 100;
  app.add_option("--live-dir", live_dir,
                 "package a live stream for HTTP caches into DIR (docs/broadcast.md): seg_NNNNN.pK parts, "
                 "seg_NNNNN.hrec segments and live.json, from --connect HOST:PORT or --source synthetic (paced in "
                 "real time); --segment-seconds, --part-ms, --window; runs until --duration or Ctrl-C");
  app.add_option("--part-ms", part_ms, "--live-dir: target part length, ms")->capture_default_str();
  app.add_option("--window", window, "--live-dir: segments listed in live.json")->capture_default_str();
  app.add_option("--cache-bucket-ms", cache_bucket_ms,
                 "--live-dir: players key their live.json polls by time buckets this long, so an edge asks the "
                 "origin about once per bucket (0: every poll reaches the origin)")
      ->capture_default_str();
  app.add_flag("-q,--quiet", quiet, "no progress output");
  out_opt->excludes(info_opt)->excludes(cut_opt);
  info_opt->excludes(cut_opt);
  CLI11_PARSE(app, argc, argv);
  if (!connect.empty() && app.count("--duration") == 0) duration = 0;

  if (!info_path.empty()) return Info(info_path, deep, json, salvage);
  if (!cut_path.empty()) {
    if (out_dir.empty()) return Fail(holo::InvalidArgument("--cut needs --out-dir DIR"));
    return Cut(cut_path, segment_s, out_dir, quiet);
  }
  if (!live_dir.empty()) {
    if (!out.empty()) return Fail(holo::InvalidArgument("--live-dir and --out exclude each other"));
    if (app.count("--duration") == 0) duration = 0;
    holo::record::LivePackagerOptions lo;
    lo.dir = live_dir;
    lo.segment_us = static_cast<int64_t>(segment_s * 1e6);
    lo.part_us = static_cast<int64_t>(part_ms * 1e3);
    lo.window_segments = window;
    lo.cache_bucket_ms = cache_bucket_ms;
    return PackageLive(lo, connect, source, token, duration, tls, ca_file, connect_timeout_s, quiet);
  }
  if (out.empty()) return Fail(holo::InvalidArgument("nothing to do: pass --out FILE, --info FILE or --cut FILE (see --help)"));
  if (!connect.empty())
    return RecordLive(out, connect, token, duration, max_bytes, overwrite, sync_mb, tls, ca_file, connect_timeout_s,
                      quiet);
  return Record(out, source, duration, max_bytes, codec, step_mm, !no_audio, realtime, overwrite, sync_mb, quiet);
}
