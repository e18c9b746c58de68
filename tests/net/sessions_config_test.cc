// Server config and two-site call config: parsing and validation.
#include <gtest/gtest.h>

#include <cmath>

#include "client/net/call_config.h"
#include "common/file_util.h"
#include "net/server_config.h"
#include "test_util.h"

namespace holo::net {
namespace {

TEST(NetConfig, ServerConfigParsesEveryKey) {
  auto c = ParseServerConfig(R"(
name: site-a
listen: 0.0.0.0:7000
publisher_token: p
viewer_token: v
max_viewers: 200
max_publishers: 4
max_pending: 32
max_message_bytes: 65536
handshake_timeout_s: 2.5
idle_timeout_s: 20
ping_interval_s: 0.5
queue_video_frames: 4
queue_priority_messages: 256
fragment_bytes: 32768
threads: 3
tls: {enabled: true, cert: a.pem, key: a.key}
layers: {adaptive: false, down_queue_s: 0.5, kernel_backlog_s: 0.2, throughput_window_s: 2, busy_fraction: 0.6,
         down_throughput: 0.8, up_hold_s: 3, max_up_hold_s: 60, up_headroom: 1.5, stable_s: 30, probe_s: 0.5}
)");
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  EXPECT_FALSE(c->layers.adaptive);
  EXPECT_DOUBLE_EQ(c->layers.down_queue_s, 0.5);
  EXPECT_DOUBLE_EQ(c->layers.kernel_backlog_s, 0.2);
  EXPECT_DOUBLE_EQ(c->layers.throughput_window_s, 2);
  EXPECT_DOUBLE_EQ(c->layers.busy_fraction, 0.6);
  EXPECT_DOUBLE_EQ(c->layers.down_throughput, 0.8);
  EXPECT_DOUBLE_EQ(c->layers.up_hold_s, 3);
  EXPECT_DOUBLE_EQ(c->layers.max_up_hold_s, 60);
  EXPECT_DOUBLE_EQ(c->layers.up_headroom, 1.5);
  EXPECT_DOUBLE_EQ(c->layers.stable_s, 30);
  EXPECT_DOUBLE_EQ(c->layers.probe_s, 0.5);
  EXPECT_EQ(c->name, "site-a");
  EXPECT_EQ(c->host, "0.0.0.0");
  EXPECT_EQ(c->port, 7000);
  EXPECT_EQ(c->max_viewers, 200);
  EXPECT_EQ(c->max_message_bytes, 65536u);
  EXPECT_DOUBLE_EQ(c->handshake_timeout_s, 2.5);
  EXPECT_EQ(c->queue_video_frames, 4);
  EXPECT_EQ(c->threads, 3);
  EXPECT_TRUE(c->tls.enabled);
  EXPECT_EQ(c->tls.key_file, "a.key");
}

TEST(NetConfig, ServerConfigErrorsNameTheKey) {
  auto expect_error = [](const std::string& yaml, const std::string& needle) {
    auto c = ParseServerConfig(yaml, "site.yaml");
    ASSERT_FALSE(c.ok()) << yaml;
    EXPECT_NE(c.status().message().find(needle), std::string::npos) << c.status().ToString();
    EXPECT_NE(c.status().message().find("site.yaml"), std::string::npos);
  };
  expect_error("publisher_token: p\nviewer_token: v\nmax_viewer: 3\n", "max_viewer: unknown key");
  expect_error("publisher_token: p\nviewer_token: v\nmax_viewers: 0\n", "max_viewers");
  expect_error("publisher_token: p\nviewer_token: v\nmax_viewers: lots\n", "max_viewers: must be a number");
  expect_error("viewer_token: v\n", "publisher_token: must be set");
  expect_error("publisher_token: same\nviewer_token: same\n", "must differ");
  expect_error("publisher_token: p\nviewer_token: v\nmax_message_bytes: 999999999\n", "max_message_bytes");
  expect_error("publisher_token: p\nviewer_token: v\nhandshake_timeout_s: .nan\n", "handshake_timeout_s");
  expect_error("publisher_token: p\nviewer_token: v\nlisten: nowhere\n", "HOST:PORT");
  expect_error("publisher_token: p\nviewer_token: v\nlisten: 1.2.3.4:99999\n", "port");
  expect_error("publisher_token: p\nviewer_token: v\ntls: {enabled: true}\n", "tls");
  expect_error("publisher_token: p\nviewer_token: v\ntls: {enabled: true, crt: x}\n", "tls.crt: unknown key");
  expect_error("publisher_token: p\nviewer_token: v\nlayers: {up_hedroom: 2}\n", "layers.up_hedroom: unknown key");
  expect_error("publisher_token: p\nviewer_token: v\nlayers: {up_headroom: 0.5}\n", "layers.up_headroom");
  expect_error("publisher_token: p\nviewer_token: v\nlayers: {up_hold_s: fast}\n", "up_hold_s: must be a number");
  expect_error("publisher_token: p\nviewer_token: v\nlayers: 3\n", "layers");
  expect_error("publisher_token: [p\n", "not valid YAML");
  expect_error("- a\n- b\n", "map");
  expect_error("publisher_token: p\nviewer_token: v\n[a]: 1\n", "keys must be names");
}

TEST(NetConfig, RelativeTlsFilesAreNextToTheConfigFile) {
  const std::string dir = test::MakeTempDir("sessions_config");
  ASSERT_TRUE(WriteStringToFile(dir + "/site.yaml", "publisher_token: p\nviewer_token: v\n"
                                                    "tls: {enabled: true, cert: site.crt, key: /keys/site.key}\n")
                  .ok());
  auto s = LoadServerConfig(dir + "/site.yaml");
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  EXPECT_EQ(s->tls.cert_file, dir + "/site.crt");
  EXPECT_EQ(s->tls.key_file, "/keys/site.key");
  ASSERT_TRUE(WriteStringToFile(dir + "/call.yaml", "local: {address: 'a:1', publisher_token: p}\n"
                                                    "remote: {address: 'b:2', viewer_token: v}\n"
                                                    "room: {preset: face-to-face}\ntls: {enabled: true, ca: ca.pem}\n")
                  .ok());
  auto c = LoadCallConfig(dir + "/call.yaml");
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  EXPECT_EQ(c->tls_ca_file, dir + "/ca.pem");
}

TEST(NetConfig, CallConfigFaceToFace) {
  auto c = ParseCallConfig(R"(
local:  {name: alice-room, address: 127.0.0.1:7001, publisher_token: pa, viewer_token: va}
remote: {name: bob-room, address: "[::1]:7002", viewer_token: vb}
room:   {preset: face-to-face, gap_m: 0.8}
)");
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  EXPECT_EQ(c->local.port, 7001);
  EXPECT_EQ(c->remote.host, "::1");
  EXPECT_EQ(c->remote.viewer_token, "vb");
  // A remote user 1 m in front of their display appears 1.8 m away, facing us.
  const Eigen::Vector3f p = c->room.local_from_remote * Eigen::Vector3f(1, 0, 0);
  EXPECT_NEAR(p.x(), -1.8f, 1e-5f);
  EXPECT_NEAR(p.y(), 0.0f, 1e-5f);
  const audio::RoomLink ref = audio::FaceToFaceLink(0.8f);
  EXPECT_TRUE(c->room.local_from_remote.matrix().isApprox(ref.local_from_remote.matrix()));
}

TEST(NetConfig, CallConfigExplicitTransform) {
  auto c = ParseCallConfig(R"(
local:  {address: 10.0.0.1:7000, publisher_token: pa}
remote: {address: 10.0.0.2:7000, viewer_token: vb}
room:   {yaw_deg: 90, translation_m: [1, 2, 0]}
tls:    {enabled: true, ca: sites.pem}
)");
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  const Eigen::Vector3f p = c->room.local_from_remote * Eigen::Vector3f(1, 0, 0);
  EXPECT_NEAR(p.x(), 1.0f, 1e-5f);
  EXPECT_NEAR(p.y(), 3.0f, 1e-5f);
  EXPECT_TRUE(c->tls);
  EXPECT_EQ(c->tls_ca_file, "sites.pem");
  EXPECT_EQ(c->local.name, "local");
}

TEST(NetConfig, CallConfigErrorsNameTheKey) {
  auto expect_error = [](const std::string& yaml, const std::string& needle) {
    auto c = ParseCallConfig(yaml, "call.yaml");
    ASSERT_FALSE(c.ok()) << yaml;
    EXPECT_NE(c.status().message().find(needle), std::string::npos) << c.status().ToString();
  };
  const std::string sites = "local: {address: 'a:1', publisher_token: p}\nremote: {address: 'b:2', viewer_token: v}\n";
  expect_error(sites, "room: missing");
  expect_error(sites + "room: {preset: side-by-side}\n", "room.preset");
  expect_error(sites + "room: {preset: face-to-face, yaw_deg: 3}\n", "room.yaw_deg: not with a preset");
  expect_error(sites + "room: {yaw_deg: 1000}\n", "room.yaw_deg");
  expect_error(sites + "room: {translation_m: [1, 2]}\n", "room.translation_m");
  expect_error(sites + "room: {translation_m: [1, 2, .inf]}\n", "room.translation_m");
  expect_error(sites + "room: {gap_m: 1}\n", "room.gap_m");
  expect_error("local: {address: 'a:1'}\nremote: {address: 'b:2', viewer_token: v}\nroom: {preset: face-to-face}\n",
               "local.publisher_token");
  expect_error("local: {address: 'a:1', publisher_token: p}\nremote: {address: 'b:2'}\nroom: {preset: face-to-face}\n",
               "remote.viewer_token");
  expect_error("local: {address: 'a', publisher_token: p}\nremote: {address: 'b:2', viewer_token: v}\n"
               "room: {preset: face-to-face}\n",
               "local.address");
  expect_error("local: {address: 'a:1', publisher_token: p}\nremote: {address: 'a:1', viewer_token: v}\n"
               "room: {preset: face-to-face}\n",
               "remote.address");
  expect_error(sites + "room: {preset: face-to-face}\nextra: 1\n", "extra: unknown key");
  expect_error(sites + "room: {preset: face-to-face, [yaw_deg]: 1}\n", "room: keys must be names");
}

}  // namespace
}  // namespace holo::net
