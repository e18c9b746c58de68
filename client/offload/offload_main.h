// Entry points of `holoport-client --render-host …` and `holoport-client
// --thin …` (docs/offload.md); each parses its own command line.
#pragma once

namespace holo::offload {

int RenderHostMain(int argc, char** argv);
int ThinClientMain(int argc, char** argv);

}  // namespace holo::offload
