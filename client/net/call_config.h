// Two-site call configuration (YAML; docs/sessions.md): both sites'
// addresses and tokens and how the remote room maps into the local one.
//
// A participant's client publishes its own audio+pose to its LOCAL site
// (publisher token; the site relays it to its viewers, among them the remote
// participant's client) and views the REMOTE site (viewer token).
#pragma once

#include <string>

#include "audio/room.h"
#include "common/status.h"

namespace holo::net {

struct CallSite {
  std::string name;
  std::string host;
  uint16_t port = 0;
  std::string publisher_token;  // local site: to publish the own audio+pose
  std::string viewer_token;     // remote site: to watch it (local: optional, own geometry for occlusion)
};

struct CallConfig {
  CallSite local;
  CallSite remote;
  // p_local = local_from_remote · p_remote (audio placement and rendering).
  audio::RoomLink room;
  bool tls = false;
  std::string tls_ca_file;  // PEM of the sites' certificates (self-signed ones too)
};

// Keys: local {name, address HOST:PORT, publisher_token, viewer_token?},
// remote {name, address, viewer_token}, room {preset: face-to-face, gap_m} or
// room {yaw_deg, pitch_deg, roll_deg, translation_m: [x, y, z]}, tls {enabled, ca}.
// Unknown keys, missing tokens, bad numbers: InvalidArgument naming the key.
StatusOr<CallConfig> ParseCallConfig(const std::string& yaml_text, const std::string& source = "call config");
StatusOr<CallConfig> LoadCallConfig(const std::string& path);

}  // namespace holo::net
