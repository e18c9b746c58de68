// The viewer connected to a site (docs/viewer.md "Connecting"): a synthetic
// site received over loopback renders like the ground truth; holoport-client
// --connect survives the site restarting, malformed frames from a fake
// server, and a rig change mid-stream. Count-based (no timing asserts).
#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

#include <array>
#include <cmath>
#include <atomic>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "audio/wav.h"
#include "client/client_program.h"
#include "client/net/participant.h"
#include "client/render/gl_context.h"
#include "client/render/renderer.h"
#include "client/render/view.h"
#include "common/image_io.h"
#include "common/metrics/image_metrics.h"
#include "common/pose.h"
#include "net/net_fixtures.h"
#include "net/session_server.h"
#include "net/site_client.h"
#include "net/wire_message.h"
#include "protocol/geometry_codec.h"
#include "protocol/messages.h"
#include "protocol/test_meshes.h"
#include "server/net/site_publisher.h"
#include "studio/studio.h"
#include "studio/workloads.h"
#include "test_util.h"

namespace holo {
namespace {

// One quality layer: what is checked here is every frame on the full layer,
// not the layer policy (tests/net/fanout_layers_test.cc), which could move a
// viewer slowed by a loaded machine to the reduced layer.
net::SitePublisherOptions FullLayerOnly() {
  net::SitePublisherOptions o;
  o.reduced.enabled = false;
  return o;
}

// Stated threshold: projective texturing of the received (G1 + C1 decoded)
// S8-QVGA frame vs the studio's ground-truth render from the same pose, mean
// over 4 novel views at 640x480, inside the true foreground. The same
// measurement on the exact (never encoded) frame gives ≈ 25 dB
// (render_test); the wire costs a little.
constexpr double kReceivedPsnrThresholdDb = 22.0;

net::ServerConfig Loopback(uint16_t port = 0) {
  net::ServerConfig c = test::LoopbackConfig(port);
  c.name = "connect-test-site";
  c.publisher_token = "pub";
  c.viewer_token = "view";
  c.threads = 1;
  return c;
}

struct StudioContent {
  Rig rig;
  Mesh mesh;
  std::vector<ImageRgb8> color;
  std::vector<ImageGray8> mask;
  std::unique_ptr<SyntheticStudio> studio;
};

StudioContent MakeStudio(const std::string& workload, int64_t frame) {
  StudioContent c;
  auto w = GetWorkload(workload);
  HOLO_CHECK(w.ok());
  StudioOptions so = w->studio;
  so.color_variation = false;
  so.threads = 2;
  auto studio = SyntheticStudio::Create(w->rig, so);
  HOLO_CHECK(studio.ok());
  c.studio = std::move(*studio);
  c.rig = w->rig;
  RgbdFrameSet fs;
  StudioGroundTruth gt;
  c.studio->RenderFrame(frame, &fs, &gt);
  c.mesh = std::move(gt.foreground_mesh);
  for (size_t p = 0; p < fs.frames.size(); ++p) {
    c.color.push_back(fs.frames[p].color);
    c.mask.push_back(gt.mask[p]);
  }
  return c;
}

Status PublishStudio(net::SitePublisher& pub, const StudioContent& c, int64_t index) {
  std::vector<net::PodColor> pods;
  for (size_t p = 0; p < c.color.size(); ++p) {
    pods.push_back({static_cast<uint16_t>(c.rig.pods[p].id), &c.color[p], &c.mask[p]});
  }
  net::PublishTimings t;
  return pub.Publish(index, net::WallUs(), c.mesh, pods, &t);
}

CameraModel NovelCamera(int w, int h, float az_deg) {
  // As render_test's novel views: radius 2 m, eye at 1.6 m, looking at (0, 0, 1).
  const float az = az_deg * static_cast<float>(M_PI) / 180.0f;
  CameraModel cam;
  cam.intrinsics = Intrinsics::FromFov(w, h, 60.0f);
  cam.world_from_camera = LookAt(Eigen::Vector3f(2.0f * std::cos(az), 2.0f * std::sin(az), 1.6f), {0, 0, 1.0f});
  return cam;
}

// ---- the received frame renders like the ground truth ----

TEST(ConnectTest, ReceivedSyntheticSiteRendersLikeGroundTruth) {
  StudioContent c = MakeStudio("S8-QVGA", 40);
  auto server = net::Server::Start(Loopback());
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  (*server)->SetRig(c.rig);
  net::SitePublisher pub(server->get(), FullLayerOnly());
  net::ClientOptions o;
  o.port = (*server)->port();
  o.token = "view";
  o.color_wait_s = 1.0;
  auto client = net::SiteClient::Start(o);
  ASSERT_TRUE(client.ok());
  ASSERT_TRUE((*client)->WaitConnected(10));
  net::ReceivedFrame f;
  bool got = false;
  for (int i = 0; i < 50 && !got; ++i) {
    ASSERT_TRUE(PublishStudio(pub, c, i).ok());
    got = (*client)->WaitFrame(&f, 0.2) && f.has_mesh && f.has_color;
  }
  ASSERT_TRUE(got) << "no frame with mesh and colour received";
  auto rig = (*client)->rig();
  ASSERT_TRUE(rig.has_value());
  ASSERT_EQ(rig->pods.size(), c.rig.pods.size());
  ASSERT_EQ(f.images.size(), c.rig.pods.size());

  auto ctx = render::CreateHeadlessContext();
  ASSERT_TRUE(ctx.ok()) << ctx.status().ToString();
  ASSERT_TRUE((*ctx)->MakeCurrent().ok());
  auto renderer = render::Renderer::Create();
  ASSERT_TRUE(renderer.ok());
  ASSERT_TRUE((*renderer)->SetRemoteMesh(f.mesh).ok());
  std::vector<const ImageRgb8*> images;
  for (const auto& pod : rig->pods) {
    for (const auto& im : f.images) {
      if (im.pod_id == pod.id) images.push_back(&im.image);
    }
  }
  ASSERT_EQ(images.size(), rig->pods.size());
  ASSERT_TRUE((*renderer)->SetPodImages(*rig, images).ok());
  ASSERT_TRUE((*renderer)->UpdateVisibility().ok());
  auto target = render::OffscreenTarget::Create(640, 480);
  ASSERT_TRUE(target.ok());
  double sum = 0;
  int n = 0;
  const std::string dir = test::MakeTempDir("connect_test");
  for (float az : {22.5f, 112.5f, 202.5f, 292.5f}) {
    const CameraModel cam = NovelCamera(640, 480, az);
    ImageRgb8 truth, shown;
    ImageGray8 mask;
    c.studio->RenderView(40, cam, &truth, nullptr, &mask);
    (*target)->Bind();
    render::RenderSettings rs;
    rs.background = {0, 0, 0};
    rs.mode = render::ColorMode::kProjective;
    ASSERT_TRUE((*renderer)->Render(cam, rs, {0, 0, 640, 480}).ok());
    ASSERT_TRUE((*target)->ReadRgb(&shown).ok());
    auto psnr = metrics::ComputePsnr(shown, truth, &mask);
    ASSERT_TRUE(psnr.ok());
    std::printf("azimuth %.1f: received frame %lld, projective %.2f dB\n", az, static_cast<long long>(f.frame_index),
                *psnr);
    sum += *psnr;
    ++n;
    if (n == 1) {
      ASSERT_TRUE(WriteImageRgb8(dir + "/received.png", shown).ok());
      ASSERT_TRUE(WriteImageRgb8(dir + "/truth.png", truth).ok());
    }
  }
  std::printf("mean %.2f dB (threshold %.1f; images in %s)\n", sum / n, kReceivedPsnrThresholdDb, dir.c_str());
  EXPECT_GT(sum / n, kReceivedPsnrThresholdDb);
  (*client)->Stop();
  (*server)->Stop();
}

// ---- the program ----

using test::ClientPath;
using test::RunResult;

// Runs holoport-client with `args` in a thread; Wait() collects the result.
class ClientRun {
 public:
  explicit ClientRun(const std::string& args) {
    thread_ = std::thread([this, args] {
      r_ = test::RunCommand("env -u DISPLAY " + ClientPath() + " " + args, [this] { started_ = true; });
      done_ = true;
    });
    // The child exists before the caller opens sockets (which it would inherit).
    while (!started_) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  ~ClientRun() {
    if (thread_.joinable()) thread_.join();
  }
  bool done() const { return done_; }
  RunResult Wait() {
    thread_.join();
    return r_;
  }

 private:
  std::thread thread_;
  RunResult r_;
  std::atomic<bool> done_{false}, started_{false};
};

nlohmann::json ReadStats(const std::string& dir) {
  std::ifstream f(dir + "/stats.json");
  nlohmann::json j;
  if (f) f >> j;
  return j;
}

Mesh SmallMesh() { return test::NoisySphere(20, 30); }

// Publishes `count` frames of a small mesh from index `first`, ~30 fps.
void PublishSpheres(net::Server* server, int64_t first, int count) {
  net::SitePublisher pub(server, FullLayerOnly());
  const Mesh m = SmallMesh();
  for (int i = 0; i < count; ++i) {
    net::PublishTimings t;
    HOLO_CHECK(pub.Publish(first + i, net::WallUs(), m, {}, &t).ok());
    std::this_thread::sleep_for(std::chrono::milliseconds(33));
  }
}

// A free port below the kernel's ephemeral range (32768+): a client retrying
// a local port inside it can connect to itself while the site is away.
uint16_t PickPort() {
  for (int i = 0; i < 50; ++i) {
    const auto p = static_cast<uint16_t>(20000 + (getpid() * 7 + i * 131) % 12000);
    auto probe = net::Server::Start(Loopback(p));
    if (probe.ok()) {
      (*probe)->Stop();
      return p;
    }
  }
  return 0;
}

// The programs start before the sites: a listening socket created before
// popen() would be inherited by the child and keep the port open.
TEST(ConnectTest, ProgramReconnectsWhenTheSiteRestarts) {
  // The program starts first: a listening socket created before popen()
  // would be inherited by the child and keep the port after the site stops.
  // The port is below the kernel's ephemeral range (a client retrying a
  // local port inside it can connect to itself while the site is away).
  const uint16_t port = PickPort();
  ASSERT_NE(port, 0);
  const std::string dir = test::MakeTempDir("connect_restart");
  ClientRun run("--connect 127.0.0.1:" + std::to_string(port) +
                " --token view --headless --seconds 9 --no-png --width 160 --height 120 --out " + dir);
  auto server = test::StartServerRetrying(Loopback(port));
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  PublishSpheres(server->get(), 0, 45);  // ~1.5 s
  (*server)->Stop();
  server->reset();
  std::this_thread::sleep_for(std::chrono::milliseconds(800));  // the site is away
  auto again = test::StartServerRetrying(Loopback(port));
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  // Frames resume with new indices, until the program ends (at 9 s; a
  // reconnect attempt that hit the old site's closing socket waits out its
  // connect timeout before the next try).
  for (int64_t k = 1000; !run.done(); k += 15) PublishSpheres(again->get(), k, 15);
  const RunResult r = run.Wait();
  (*again)->Stop();
  ASSERT_FALSE(r.signaled) << r.output;
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("reconnecting"), std::string::npos) << r.output;
  const nlohmann::json j = ReadStats(dir);
  ASSERT_FALSE(j.is_null()) << r.output;
  EXPECT_GE(j["connects"].get<int>(), 2) << r.output;
  EXPECT_GE(j["last_frame_index"].get<int64_t>(), 1000) << r.output;  // frames after the restart were shown
  EXPECT_GE(j["frames_new"].get<int64_t>(), 10) << r.output;
}

// A fake site: listens, answers Hello with Welcome, then sends what the test says.
class FakeSite {
 public:
  FakeSite() {
    fd_ = socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
    HOLO_CHECK(fd_ >= 0);
    int one = 1;
    setsockopt(fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof one);
    sockaddr_in a{};
    a.sin_family = AF_INET;
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    HOLO_CHECK(bind(fd_, reinterpret_cast<sockaddr*>(&a), sizeof a) == 0);
    HOLO_CHECK(listen(fd_, 4) == 0);
    socklen_t len = sizeof a;
    getsockname(fd_, reinterpret_cast<sockaddr*>(&a), &len);
    port_ = ntohs(a.sin_port);
  }
  ~FakeSite() {
    if (conn_ >= 0) close(conn_);
    close(fd_);
  }
  uint16_t port() const { return port_; }
  // Accepts one connection, reads (and ignores) its Hello, sends Welcome.
  bool Accept(double timeout_s) {
    timeval tv{static_cast<time_t>(timeout_s), 0};
    setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    if (conn_ >= 0) close(conn_);
    conn_ = accept(fd_, nullptr, nullptr);
    if (conn_ < 0) return false;
    std::array<uint8_t, 4096> buf;
    setsockopt(conn_, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
    if (recv(conn_, buf.data(), buf.size(), 0) <= 0) return false;
    protocol::Welcome w;
    w.session_id = 7;
    w.server_name = "fake-site";
    return Send(protocol::EncodeMessage({}, w));
  }
  bool Send(const std::vector<uint8_t>& bytes) {
    return conn_ >= 0 && send(conn_, bytes.data(), bytes.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(bytes.size());
  }
  bool SendMesh(int64_t index, std::vector<uint8_t> blob) {
    protocol::MeshFrame mf;
    mf.frame_index = index;
    mf.data = std::move(blob);
    protocol::Header h;
    h.stream_id = 1;
    h.sequence = static_cast<uint32_t>(index);
    h.capture_time_us = net::WallUs();
    return Send(protocol::EncodeMessage(h, mf));
  }

 private:
  int fd_ = -1, conn_ = -1;
  uint16_t port_ = 0;
};

TEST(ConnectTest, MalformedFramesFromAFakeSiteAreReportedNotFatal) {
  FakeSite site;
  std::vector<uint8_t> good;
  ASSERT_TRUE(protocol::EncodeGeometry(SmallMesh(), {}, &good).ok());
  const std::string dir = test::MakeTempDir("connect_malformed");
  ClientRun run("--connect 127.0.0.1:" + std::to_string(site.port()) +
                " --token view --headless --seconds 5 --no-png --width 160 --height 120 --out " + dir);
  ASSERT_TRUE(site.Accept(10));
  for (int i = 0; i < 5; ++i) ASSERT_TRUE(site.SendMesh(i, good));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  // A MeshFrame whose geometry blob is garbage: a decode error, the connection stays.
  std::vector<uint8_t> garbage(good.size(), 0xA5);
  ASSERT_TRUE(site.SendMesh(5, garbage));
  std::vector<uint8_t> truncated(good.begin(), good.begin() + static_cast<std::ptrdiff_t>(good.size() / 2));
  ASSERT_TRUE(site.SendMesh(6, truncated));
  for (int i = 7; i < 10; ++i) ASSERT_TRUE(site.SendMesh(i, good));
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  // Bytes that are no protocol frame at all: the client drops the connection
  // (protocol violation) and reconnects.
  std::vector<uint8_t> junk(64, 0x42);
  site.Send(junk);
  ASSERT_TRUE(site.Accept(10)) << "the client did not reconnect after the malformed bytes";
  for (int i = 100; i < 110; ++i) {
    ASSERT_TRUE(site.SendMesh(i, good));
    std::this_thread::sleep_for(std::chrono::milliseconds(30));
  }
  const RunResult r = run.Wait();
  ASSERT_FALSE(r.signaled) << r.output;
  ASSERT_EQ(r.exit_code, 0) << r.output;
  const nlohmann::json j = ReadStats(dir);
  ASSERT_FALSE(j.is_null()) << r.output;
  EXPECT_GE(j["decode_errors"].get<int>(), 2) << r.output;
  EXPECT_GE(j["connects"].get<int>(), 2) << r.output;
  EXPECT_GE(j["last_frame_index"].get<int64_t>(), 100) << r.output;
  EXPECT_NE(r.output.find("site connection"), std::string::npos) << r.output;  // the loss was reported
}

TEST(ConnectTest, RigChangeMidStreamIsReportedAndRenderingContinues) {
  StudioContent a = MakeStudio("S8-QVGA", 10);
  StudioContent b = MakeStudio("S4-QVGA", 10);
  const uint16_t port = PickPort();
  ASSERT_NE(port, 0);
  const std::string dir = test::MakeTempDir("connect_rig");
  ClientRun run("--connect 127.0.0.1:" + std::to_string(port) +
                " --token view --headless --seconds 6 --no-png --width 160 --height 120 --out " + dir);
  auto server = test::StartServerRetrying(Loopback(port));
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  (*server)->SetRig(a.rig);
  net::SitePublisher pub(server->get(), FullLayerOnly());
  std::this_thread::sleep_for(std::chrono::milliseconds(500));
  for (int i = 0; i < 30; ++i) {
    ASSERT_TRUE(PublishStudio(pub, a, i).ok());
    std::this_thread::sleep_for(std::chrono::milliseconds(40));
  }
  // The site is recalibrated with another rig: 8 → 4 pods.
  (*server)->SetRig(b.rig);
  std::this_thread::sleep_for(std::chrono::milliseconds(100));
  for (int i = 1000; i < 1040; ++i) {
    ASSERT_TRUE(PublishStudio(pub, b, i).ok());
    std::this_thread::sleep_for(std::chrono::milliseconds(40));
  }
  const RunResult r = run.Wait();
  (*server)->Stop();
  ASSERT_FALSE(r.signaled) << r.output;
  ASSERT_EQ(r.exit_code, 0) << r.output;
  EXPECT_NE(r.output.find("rig changed mid-stream"), std::string::npos) << r.output;
  const nlohmann::json j = ReadStats(dir);
  ASSERT_FALSE(j.is_null()) << r.output;
  EXPECT_GE(j["rig_changes"].get<int>(), 1) << r.output;
  EXPECT_EQ(j["rig_pods"].get<int>(), 4) << r.output;
  EXPECT_GE(j["last_frame_index"].get<int64_t>(), 1000) << r.output;
  EXPECT_EQ(j["bad_frames"].get<int>(), 0) << r.output;
}

// The shared participant code (holoport-client --call, holoport-call):
// two sites, two participants; each hears the other's voice, spatialized
// in front of it (face to face), and writes the stereo WAV.
TEST(ConnectTest, CallParticipantsHearEachOtherSpatialized) {
  auto site_a = net::Server::Start(Loopback());
  auto site_b = net::Server::Start(Loopback());
  ASSERT_TRUE(site_a.ok() && site_b.ok());
  const std::string dir = test::MakeTempDir("connect_call");
  auto config = [&](uint16_t local, uint16_t remote) {
    return "local: {name: here, address: 127.0.0.1:" + std::to_string(local) +
           ", publisher_token: pub}\nremote: {name: there, address: 127.0.0.1:" + std::to_string(remote) +
           ", viewer_token: view}\nroom: {preset: face-to-face, gap_m: 0.5}\n";
  };
  std::vector<std::unique_ptr<net::Participant>> people;
  for (int k = 0; k < 2; ++k) {
    auto call = net::ParseCallConfig(k == 0 ? config((*site_a)->port(), (*site_b)->port())
                                            : config((*site_b)->port(), (*site_a)->port()));
    ASSERT_TRUE(call.ok()) << call.status().ToString();
    net::ParticipantOptions po;
    po.call = *call;
    po.name = k == 0 ? "alice" : "bob";
    po.audio_out = dir + "/" + po.name + ".wav";  // no --audio-in: the 440 Hz tone
    auto p = net::Participant::Start(po);
    ASSERT_TRUE(p.ok()) << p.status().ToString();
    people.push_back(std::move(*p));
  }
  ASSERT_TRUE(test::Eventually([&] {
    return people[0]->stats().remote_audio_frames >= 100 && people[1]->stats().remote_audio_frames >= 100;
  }, 30.0));
  for (int k = 0; k < 2; ++k) {
    ASSERT_TRUE(people[k]->Stop().ok());
    const net::ParticipantStats s = people[k]->stats();
    EXPECT_GE(s.voice_frames_sent, 100);
    EXPECT_EQ(s.remote_speakers, 1);
    // Face to face with a 0.5 m gap: the other head (2 m from its display) is 2.5 m in front, at eye height.
    EXPECT_NEAR(s.remote_x, -2.5f, 0.01f);
    EXPECT_NEAR(s.remote_z, 1.6f, 0.01f);
    EXPECT_LT(std::abs(s.remote_azimuth_deg), 40.0f);
    auto wav = audio::ReadWav(dir + "/" + (k == 0 ? "alice" : "bob") + ".wav");
    ASSERT_TRUE(wav.ok()) << wav.status().ToString();
    EXPECT_EQ(wav->channels, 2);
    EXPECT_EQ(wav->sample_rate, 48000);
    double sum_sq = 0;
    for (float v : wav->samples) sum_sq += static_cast<double>(v) * v;
    const double rms = std::sqrt(sum_sq / static_cast<double>(wav->samples.size()));
    std::printf("%s: %zu frames heard, %.2f s of stereo, RMS %.4f, audio delay %.1f ms, azimuth %.1f deg\n",
                k == 0 ? "alice" : "bob", static_cast<size_t>(s.remote_audio_frames), wav->frames() / 48000.0, rms,
                s.audio_delay_ms, s.remote_azimuth_deg);
    EXPECT_GT(rms, 1e-3);  // the tone is heard (0.1 amplitude at 2.5 m)
  }
}

}  // namespace
}  // namespace holo
