// holoport-bench audio's lean-frame figures (bench_audio_lean.cc).
#pragma once

#include "bench.h"

namespace holo::bench {

// kbps per frame format, fwSNRseg per Opus setting, pose error, mouth-to-ear
// of classic and lean frames. Returns the process exit code.
int RunLeanFrames(const BenchArgs& args);

}  // namespace holo::bench
