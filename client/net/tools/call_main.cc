// holoport-call: a headless session participant for trying sessions out
// without the GL viewer (docs/sessions.md).
//
//   holoport-call --watch HOST:PORT --token T      watch a site (broadcast viewer)
//   holoport-call --config call.yaml               one side of a two-site call
//
// Watching prints frames per second, latency and RTT and can write the last
// decoded mesh as PLY. In a call it publishes its participant's audio+pose
// (a synthetic 20 ms PCM tone and a slowly turning head) to the local site,
// watches the remote site, and prints where the remote participant's voice
// sits in the local room (the call config's room transform).
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <thread>

#include <CLI/CLI.hpp>

#include "audio/room.h"
#include "client/net/call_config.h"
#include "client/net/site_client.h"
#include "common/mesh.h"

namespace {

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop = true; }

int Fail(const holo::Status& s) {
  std::fprintf(stderr, "holoport-call: %s\n", s.message().c_str());
  return 1;
}

int64_t NowUs() {
  return std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::system_clock::now().time_since_epoch())
      .count();
}

bool ParseAddress(const std::string& spec, std::string* host, uint16_t* port) {
  const size_t c = spec.rfind(':');
  if (c == std::string::npos || c == 0) return false;
  const long p = std::strtol(spec.c_str() + c + 1, nullptr, 10);
  if (p < 1 || p > 65535) return false;
  *host = spec.substr(0, c);
  *port = static_cast<uint16_t>(p);
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"holoport-call: watch a site, or take part in a two-site call, without a GL viewer"};
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
  CLI11_PARSE(app, argc, argv);
  std::signal(SIGINT, OnSignal);
  std::signal(SIGTERM, OnSignal);
  if (watch.empty() == config_path.empty()) return Fail(holo::InvalidArgument("give exactly one of --watch or --config"));

  holo::net::ClientOptions view;
  view.name = name;
  view.decode = !no_decode;
  holo::net::CallConfig call;
  if (!watch.empty()) {
    if (!ParseAddress(watch, &view.host, &view.port))
      return Fail(holo::InvalidArgument("--watch: expected HOST:PORT, got '" + watch + "'"));
    view.token = !token.empty() ? token : (std::getenv("HOLO_VIEWER_TOKEN") ? std::getenv("HOLO_VIEWER_TOKEN") : "");
    view.tls.enabled = tls;
    view.tls.ca_file = ca_file;
  } else {
    auto c = holo::net::LoadCallConfig(config_path);
    if (!c.ok()) return Fail(c.status());
    call = *c;
    view.host = call.remote.host;
    view.port = call.remote.port;
    view.token = call.remote.viewer_token;
    view.tls.enabled = call.tls;
    view.tls.ca_file = call.tls_ca_file;
  }
  std::atomic<int64_t> audio_heard{0};
  std::mutex last_mu;
  holo::protocol::HeadPose last_remote_head;
  holo::net::ClientCallbacks cb;
  cb.on_state = [](holo::net::ClientState s, const holo::Status& why) {
    std::fprintf(stderr, "holoport-call: view %s%s%s\n", holo::net::ClientStateName(s), why.ok() ? "" : ": ",
                 why.ok() ? "" : why.message().c_str());
  };
  cb.on_audio = [&](const holo::protocol::AudioPose& a, uint32_t) {
    ++audio_heard;
    std::lock_guard<std::mutex> l(last_mu);
    last_remote_head = a.pose;
  };
  auto viewer = holo::net::SiteClient::Start(view, cb);
  if (!viewer.ok()) return Fail(viewer.status());

  // In a call: publish the own audio+pose to the local site.
  std::unique_ptr<holo::net::SiteClient> talker;
  if (!config_path.empty()) {
    holo::net::ClientOptions pub;
    pub.host = call.local.host;
    pub.port = call.local.port;
    pub.role = holo::protocol::Role::kPublisher;
    pub.token = call.local.publisher_token;
    pub.name = name + "-voice";
    pub.tls.enabled = call.tls;
    pub.tls.ca_file = call.tls_ca_file;
    auto t = holo::net::SiteClient::Start(pub);
    if (!t.ok()) return Fail(t.status());
    talker = std::move(*t);
  }

  const auto start = std::chrono::steady_clock::now();
  auto last_report = start;
  int64_t frames = 0, frames_at_report = 0;
  holo::Mesh last_mesh;
  double latency_sum = 0;
  uint32_t seq = 0;
  auto next_audio = start;
  while (!g_stop) {
    const auto now = std::chrono::steady_clock::now();
    const double el = std::chrono::duration<double>(now - start).count();
    if (seconds > 0 && el >= seconds) break;
    holo::net::ReceivedFrame f;
    while ((*viewer)->PollFrame(&f)) {
      ++frames;
      latency_sum += f.latency_ms;
      if (f.has_mesh && !f.mesh.positions.empty()) last_mesh = std::move(f.mesh);
    }
    if (talker && now >= next_audio) {
      // 20 ms of a 440 Hz tone at 16 kHz (PCM) and a head turning slowly, 1 m in front of the display.
      holo::protocol::AudioPose a;
      a.codec = holo::protocol::AudioCodec::kPcm16;
      a.sample_rate = 16000;
      a.sequence = seq;
      a.capture_time_us = NowUs();
      a.pose = {1.0f, 0.3f * std::sin(static_cast<float>(el) * 0.5f), 1.6f, static_cast<float>(M_PI), 0, 0};
      a.audio.resize(320 * 2);
      for (int i = 0; i < 320; ++i) {
        const auto v = static_cast<int16_t>(3000 * std::sin(2 * M_PI * 440 * (seq * 320 + i) / 16000.0));
        a.audio[2 * i] = static_cast<uint8_t>(v & 0xFF);
        a.audio[2 * i + 1] = static_cast<uint8_t>((v >> 8) & 0xFF);
      }
      talker->SendAudioPose(a);
      ++seq;
      next_audio += std::chrono::milliseconds(20);
    }
    if (now - last_report >= std::chrono::seconds(2)) {
      const double dt = std::chrono::duration<double>(now - last_report).count();
      const holo::net::ClientStats s = (*viewer)->stats();
      std::fprintf(stderr, "  %.0f s: %.1f fps, %lld frames, mean latency %.1f ms, RTT %.2f ms, audio heard %lld",
                   el, (frames - frames_at_report) / dt, static_cast<long long>(frames),
                   frames ? latency_sum / frames : 0.0, s.rtt_ms, static_cast<long long>(audio_heard.load()));
      if (!config_path.empty() && audio_heard > 0) {
        std::lock_guard<std::mutex> l(last_mu);
        const holo::audio::SpeakerPlacement sp = holo::audio::PlaceRemoteSpeaker(last_remote_head, call.room);
        std::fprintf(stderr, "; remote voice at (%.2f, %.2f, %.2f) in the local room", sp.position.x(),
                     sp.position.y(), sp.position.z());
      }
      std::fprintf(stderr, "\n");
      last_report = now;
      frames_at_report = frames;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  const holo::net::ClientStats s = (*viewer)->stats();
  std::printf("{\"frames\":%lld,\"connects\":%llu,\"decode_errors\":%llu,\"mean_latency_ms\":%.3f,\"rtt_min_ms\":%.3f,"
              "\"audio_heard\":%lld,\"bytes\":%llu}\n",
              static_cast<long long>(frames), static_cast<unsigned long long>(s.connects),
              static_cast<unsigned long long>(s.decode_errors), frames ? latency_sum / frames : 0.0, s.rtt_min_ms,
              static_cast<long long>(audio_heard.load()), static_cast<unsigned long long>(s.bytes_received));
  if (!ply_path.empty()) {
    if (last_mesh.positions.empty()) return Fail(holo::NotFound("no mesh received; nothing written to " + ply_path));
    holo::Status st = holo::WritePly(ply_path, last_mesh);
    if (!st.ok()) return Fail(st);
  }
  (*viewer)->Stop();
  if (talker) talker->Stop();
  return 0;
}
