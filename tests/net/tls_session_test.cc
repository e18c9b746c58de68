// TLS sessions: a self-signed certificate made at test time with the openssl
// CLI; a client trusting it receives frames, a plain-TCP client and a client
// trusting another certificate do not get in.
#include <gtest/gtest.h>

#include <cstdlib>
#include <filesystem>

#include "client/net/raw_peer.h"
#include "net/net_fixtures.h"
#include "net/site_client.h"
#include "test_util.h"

namespace holo::net {
namespace {

using test::Eventually;

// Writes DIR/NAME.pem and DIR/NAME.key (EC P-256, CN=localhost, SAN 127.0.0.1).
bool MakeCert(const std::string& dir, const std::string& name) {
  const std::string cmd = "openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 2 "
                          "-subj /CN=localhost -addext subjectAltName=DNS:localhost,IP:127.0.0.1 -keyout '" +
                          dir + "/" + name + ".key' -out '" + dir + "/" + name + ".pem' > /dev/null 2>&1";
  return std::system(cmd.c_str()) == 0;
}

TEST(NetTls, SelfSignedSessionCarriesFramesAndRejectsOthers) {
  const std::string dir = test::MakeTempDir("holo_tls");
  if (!MakeCert(dir, "site") || !MakeCert(dir, "other")) GTEST_SKIP() << "openssl CLI not available to make test certificates (scripts/setup.sh installs openssl)";
  ServerConfig cfg = test::LoopbackConfig();
  cfg.tls.enabled = true;
  cfg.queue_video_frames = 16;
  cfg.tls.cert_file = dir + "/site.pem";
  cfg.tls.key_file = dir + "/site.key";
  test::LogCapture log;
  ServerHooks hooks;
  hooks.log = log.Hook();
  auto server = Server::Start(cfg, hooks);
  ASSERT_TRUE(server.ok()) << server.status().ToString();

  ClientOptions o;
  o.port = (*server)->port();
  o.token = "view-secret";
  o.name = "tls-viewer";
  o.tls.enabled = true;
  o.tls.ca_file = dir + "/site.pem";
  o.reconnect = false;
  o.max_pending_frames = 64;  // the 5 frames below arrive before the test pulls them (the default queue holds 4)
  auto c = SiteClient::Start(o);
  ASSERT_TRUE(c.ok()) << c.status().ToString();
  ASSERT_TRUE((*c)->WaitConnected(5.0)) << (*c)->status().ToString();
  ASSERT_TRUE(Eventually([&] { return (*server)->num_subscribed(kContentGeometry) == 1; }));
  const test::EncodedContent content = test::MakeContent(60, 80);
  for (int i = 0; i < 5; ++i)
    (*server)->PublishVideo(
        MakeVideoFrame(i, WallUs(), protocol::GeometryCodec::kG1, content.geometry, &content.color, 16384));
  for (int i = 0; i < 5; ++i) {
    ReceivedFrame f;
    ASSERT_TRUE((*c)->WaitFrame(&f, 5.0));
    EXPECT_EQ(f.frame_index, i);
    EXPECT_EQ(f.mesh.num_vertices(), content.vertices);
  }

  // A client that trusts another certificate fails the TLS handshake.
  ClientOptions bad = o;
  bad.tls.ca_file = dir + "/other.pem";
  auto b = SiteClient::Start(bad);
  ASSERT_TRUE(b.ok());
  EXPECT_FALSE((*b)->WaitConnected(5.0));
  EXPECT_NE((*b)->status().message().find("TLS"), std::string::npos) << (*b)->status().ToString();

  // Plain TCP to a TLS site: no Welcome, the connection is closed.
  auto p = RawPeer::Connect("127.0.0.1", (*server)->port());
  ASSERT_TRUE(p.ok());
  ASSERT_TRUE((*p)->SendHello(protocol::Role::kViewer, "view-secret", "plain").ok());
  EXPECT_TRUE((*p)->WaitClosed(5.0));
  EXPECT_TRUE(Eventually([&] { return log.Contains("TLS handshake failed"); }));
  EXPECT_EQ((*server)->num_viewers(), 1u);

  // A missing CA file is an error at Start.
  ClientOptions no_ca = o;
  no_ca.tls.ca_file = dir + "/missing.pem";
  auto nc = SiteClient::Start(no_ca);
  ASSERT_FALSE(nc.ok());
  EXPECT_NE(nc.status().message().find("missing.pem"), std::string::npos) << nc.status().ToString();

  // A missing certificate is a clear start-up error.
  ServerConfig missing = cfg;
  missing.tls.cert_file = dir + "/nope.pem";
  auto s2 = Server::Start(missing);
  ASSERT_FALSE(s2.ok());
  EXPECT_NE(s2.status().message().find("nope.pem"), std::string::npos);
  std::filesystem::remove_all(dir);
}

}  // namespace
}  // namespace holo::net
