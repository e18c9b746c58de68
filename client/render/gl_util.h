// Small OpenGL helpers shared by the renderer and the overlay (internal).
#pragma once

#include <string>

#include "common/status.h"

namespace holo::render {

// Compiles and links a vertex + fragment shader pair. Internal error with the
// driver's log on failure. `name` prefixes errors.
StatusOr<unsigned> BuildProgram(const std::string& name, const char* vertex_src, const char* fragment_src);
// OK, or Internal naming `where` and the pending GL errors.
Status CheckGlError(const std::string& where);

}  // namespace holo::render
