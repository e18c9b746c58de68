// `holoport-server --replay FILE`: plays a recording through ReplaySource on
// the real clock (pull mode: sleep until NextDueUs, then Pump). With --listen
// (or --net-config) the messages go to viewers through the session server's
// fan-out (ReplayServer, replay_net.h) and viewers' Control messages drive the
// replay; without, they go to --export (decoded meshes as PLY) and --stats
// (one JSON line per message with its pacing error).
#pragma once

#include <cstdint>
#include <string>

namespace holo::record {

struct ReplayCommandOptions {
  std::string path;
  double speed = 1.0;
  bool loop = false;
  double start_s = 0;
  // Stop after this many seconds of wall time (0: at the end; with loop: never).
  double max_wall_s = 0;
  std::string export_dir;  // mesh_NNNNNN.ply per MeshFrame (frame_index)
  std::string stats_path;  // "-" = stdout, "" = none
  bool quiet = false;
  // Network (ReplayServer): listen on HOST:PORT and/or a session server
  // config (YAML, docs/sessions.md). Tokens default to the env variables
  // HOLO_VIEWER_TOKEN / HOLO_PUBLISHER_TOKEN; without a publisher token a
  // random one is made (nobody publishes into a replay).
  std::string listen;
  std::string net_config;
  std::string viewer_token;
  std::string publisher_token;
  bool network() const { return !listen.empty() || !net_config.empty(); }
};

// Returns a process exit code; errors are printed to stderr.
int RunReplayCommand(const ReplayCommandOptions& options);

}  // namespace holo::record
