// holoport-call: a headless session participant for trying sessions out
// without the GL viewer (docs/sessions.md).
//
//   holoport-call --watch HOST:PORT --token T      watch a site (broadcast viewer)
//   holoport-call --config call.yaml               one side of a two-site call
//
// Watching prints frames per second, latency and RTT and can write the last
// decoded mesh as PLY. In a call (client/net/participant.h, shared with
// holoport-client --call) it publishes its participant's voice (--audio-in
// WAV, or a tone) with a synthetic head pose to the local site, watches the
// remote site, prints where the remote participant's voice sits in the local
// room (the call config's room transform) and can write the spatialized
// stereo WAV (--audio-out). --stats FILE writes one JSON line per second
// (frames and their latencies that second, the client's counters) for long
// runs such as holoport-bench soak.
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <memory>
#include <thread>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "audio/room.h"
#include "client/net/call_config.h"
#include "client/net/participant.h"
#include "common/log.h"
#include "common/mesh.h"
#include "net/site_client.h"
#include "net/wire_message.h"

namespace {

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop = true; }

int Fail(const holo::Status& s) {
  spdlog::error("holoport-call: {}", s.message());
  return 1;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"holoport-call: watch a site, or take part in a two-site call, without a GL viewer"};
  holo::AddLogLevelOption(app);
  std::string watch, token, config_path, ply_path, ca_file, name = "holoport-call";
  double seconds = 0;
  bool tls = false, no_decode = false;
  app.add_option("--watch", watch, "watch the site at HOST:PORT (broadcast viewer)");
  app.add_option("--token", token, "viewer token for --watch (default: env HOLO_VIEWER_TOKEN)");
  app.add_option("--config", config_path, "two-site call config (YAML, docs/sessions.md)");
  app.add_option("--seconds", seconds, "stop after this long (0: until Ctrl-C)");
  app.add_option("--ply", ply_path, "write the last decoded mesh to this PLY file at the end");
  app.add_option("--name", name, "client name shown in the site's log")->capture_default_str();
  app.add_flag("--tls", tls, "--watch over TLS");
  app.add_option("--ca", ca_file, "--watch: PEM file of the site's certificate (TLS)");
  app.add_flag("--no-decode", no_decode, "count frames without decoding them");
  std::string stats_path;
  app.add_option("--stats", stats_path,
                 "write one JSON line per second to this file: frames received that second, their latencies "
                 "(capture -> taken here, ms), the client's and the call's counters");
  std::string audio_in, audio_out;
  app.add_option("--audio-in", audio_in, "--config: own voice, a WAV file (looped; default: a 440 Hz tone)");
  app.add_option("--audio-out", audio_out, "--config: write the spatialized remote voices to this stereo WAV");
  std::string aec = "off", hrtf_sofa;
  app.add_option("--aec", aec, "--config: echo cancellation + noise suppression of the own voice (on with "
                               "loudspeakers, off with headphones)")
      ->check(CLI::IsMember({"on", "off"}))
      ->capture_default_str();
  int aec_filter_ms = 0;
  app.add_option("--aec-filter-ms", aec_filter_ms,
                 "--config --aec on: the echo canceller's filter length, ms: 0 = its default (140 ms, rooms up "
                 "to RT60 0.3 s); about 250 for a reverberant room (RT60 0.5 s)")
      ->capture_default_str()
      ->check(CLI::Range(0, 1000));
  app.add_option("--hrtf", hrtf_sofa, "--config: personal HRTF, a SOFA file (SimpleFreeFieldHRIR) for the "
                                      "spatialized output (default: OpenAL Soft's built-in set)");
  CLI11_PARSE(app, argc, argv);
  const bool po_aec = aec == "on";
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  if (watch.empty() == config_path.empty()) return Fail(holo::InvalidArgument("give exactly one of --watch or --config"));

  holo::net::ClientOptions view;
  view.name = name;
  view.decode = !no_decode;
  holo::net::ClientCallbacks cb;
  cb.on_state = [](holo::net::ClientState s, const holo::Status& why) {
    spdlog::info("holoport-call: view {}{}{}", holo::net::ClientStateName(s), why.ok() ? "" : ": ",
                 why.ok() ? "" : why.message().c_str());
  };
  std::unique_ptr<holo::net::SiteClient> watcher;
  std::unique_ptr<holo::net::Participant> participant;
  holo::net::SiteClient* viewer = nullptr;
  if (!watch.empty()) {
    if (!holo::net::ParseSiteAddress(watch, &view.host, &view.port))
      return Fail(holo::InvalidArgument("--watch: expected HOST:PORT, got '" + watch + "'"));
    view.token = !token.empty() ? token : (std::getenv("HOLO_VIEWER_TOKEN") ? std::getenv("HOLO_VIEWER_TOKEN") : "");
    view.tls.enabled = tls;
    view.tls.ca_file = ca_file;
    auto v = holo::net::SiteClient::Start(view, cb);
    if (!v.ok()) return Fail(v.status());
    watcher = std::move(*v);
    viewer = watcher.get();
  } else {
    auto c = holo::net::LoadCallConfig(config_path);
    if (!c.ok()) return Fail(c.status());
    holo::net::ParticipantOptions po;
    po.call = *c;
    po.name = name;
    po.audio_in = audio_in;
    po.audio_out = audio_out;
    po.aec = po_aec;
    po.aec_filter_ms = aec_filter_ms;
    po.hrtf_sofa = hrtf_sofa;
    po.view_template = view;
    auto p = holo::net::Participant::Start(po, cb);
    if (!p.ok()) return Fail(p.status());
    participant = std::move(*p);
    viewer = &participant->viewer();
  }
  std::unique_ptr<FILE, int (*)(FILE*)> stats_file(nullptr, &std::fclose);
  if (!stats_path.empty()) {
    stats_file.reset(std::fopen(stats_path.c_str(), "w"));
    if (!stats_file) return Fail(holo::Unavailable("--stats " + stats_path + ": cannot open for writing"));
  }
  std::vector<double> second_latency_ms;  // frames taken since the last --stats line
  // One --stats line: this second's frames and the counters so far.
  auto write_stats_line = [&] {
    if (!stats_file) return;
    const holo::net::ClientStats s = viewer->stats();
    nlohmann::ordered_json j;
    j["wall_us"] = holo::net::WallUs();
    j["frames"] = second_latency_ms.size();
    j["latency_ms"] = second_latency_ms;
    j["state"] = holo::net::ClientStateName(viewer->state());
    j["connects"] = s.connects;
    j["connect_failures"] = s.connect_failures;
    j["frames_received"] = s.frames_received;
    j["frames_dropped_local"] = s.frames_dropped_local;
    j["decode_errors"] = s.decode_errors;
    j["bytes"] = s.bytes_received;
    if (participant) {
      const holo::net::ParticipantStats ps = participant->stats();
      j["voice_sent"] = ps.voice_frames_sent;
      j["audio_heard"] = ps.remote_audio_frames;
      j["concealed"] = ps.concealed;
      j["late"] = ps.late;
      j["underflows"] = ps.underflows;
    }
    std::fprintf(stats_file.get(), "%s\n", j.dump().c_str());
    std::fflush(stats_file.get());
    second_latency_ms.clear();
  };
  const auto start = std::chrono::steady_clock::now();
  auto last_report = start;
  auto last_stats_line = start;
  int64_t frames = 0, frames_at_report = 0;
  holo::Mesh last_mesh;
  double latency_sum = 0;
  while (!g_stop) {
    const auto now = std::chrono::steady_clock::now();
    const double el = std::chrono::duration<double>(now - start).count();
    if (seconds > 0 && el >= seconds) break;
    holo::net::ReceivedFrame f;
    while (viewer->PollFrame(&f)) {
      ++frames;
      latency_sum += f.latency_ms;
      if (stats_file)
        second_latency_ms.push_back(f.latency_ms + static_cast<double>(holo::net::WallUs() - f.received_us) * 1e-3);
      if (f.has_mesh && !f.mesh.positions.empty()) last_mesh = std::move(f.mesh);
    }
    if (now - last_stats_line >= std::chrono::seconds(1)) {
      write_stats_line();
      last_stats_line = now;
    }
    if (now - last_report >= std::chrono::seconds(2)) {
      const double dt = std::chrono::duration<double>(now - last_report).count();
      const holo::net::ClientStats s = viewer->stats();
      std::string line =
          fmt::format("  {:.0f} s: {:.1f} fps, {} frames, mean latency {:.1f} ms, RTT {:.2f} ms", el,
                      (frames - frames_at_report) / dt, frames, frames ? latency_sum / frames : 0.0, s.rtt_ms);
      if (participant) {
        const holo::net::ParticipantStats ps = participant->stats();
        line += fmt::format(", voice sent {}, remote audio heard {}", ps.voice_frames_sent, ps.remote_audio_frames);
        if (ps.remote_audio_frames > 0) {
          line += fmt::format("; remote voice at ({:.2f}, {:.2f}, {:.2f}) in the local room, azimuth {:.0f} deg",
                              ps.remote_x, ps.remote_y, ps.remote_z, ps.remote_azimuth_deg);
        }
      }
      spdlog::info("{}", line);
      last_report = now;
      frames_at_report = frames;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  write_stats_line();
  const holo::net::ClientStats s = viewer->stats();
  int64_t audio_heard = 0, voice_sent = 0;
  double audio_delay = 0;
  if (participant) {
    holo::Status st = participant->Stop();
    const holo::net::ParticipantStats ps = participant->stats();
    audio_heard = ps.remote_audio_frames;
    voice_sent = ps.voice_frames_sent;
    audio_delay = ps.audio_delay_ms;
    if (!ps.hrtf_status.empty()) spdlog::info("holoport-call: spatializer {}", ps.hrtf_status);
    if (po_aec) {
      spdlog::info(
          "holoport-call: echo canceller on, playout->capture delay {}",
          ps.aec_delay_ms < 0 ? "not estimated (no echo heard)" : (std::to_string(ps.aec_delay_ms) + " ms").c_str());
    }
    if (!st.ok()) return Fail(st);
  }
  nlohmann::ordered_json j;
  j["frames"] = frames;
  j["connects"] = s.connects;
  j["decode_errors"] = s.decode_errors;
  j["mean_latency_ms"] = frames ? latency_sum / static_cast<double>(frames) : 0.0;
  j["rtt_min_ms"] = s.rtt_min_ms;
  j["audio_heard"] = audio_heard;
  j["voice_sent"] = voice_sent;
  j["audio_delay_ms"] = audio_delay;
  j["bytes"] = s.bytes_received;
  std::printf("%s\n", j.dump().c_str());
  if (!ply_path.empty()) {
    if (last_mesh.positions.empty()) return Fail(holo::NotFound("no mesh received; nothing written to " + ply_path));
    holo::Status st = holo::WritePly(ply_path, last_mesh);
    if (!st.ok()) return Fail(st);
  }
  if (watcher) watcher->Stop();
  return 0;
}
