// `holoport-server --replay FILE`: plays a recording through ReplaySource on
// the real clock (pull mode: sleep until NextDueUs, then Pump). Until the
// network fan-out takes the messages, they go to --export (decoded meshes as
// PLY) and --stats (one JSON line per message with its pacing error).
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
};

// Returns a process exit code; errors are printed to stderr.
int RunReplayCommand(const ReplayCommandOptions& options);

}  // namespace holo::record
