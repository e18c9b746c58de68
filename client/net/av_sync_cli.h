// The lip-sync command-line options (--av-sync, --hold-pictures,
// --max-voice-delay-ms, --max-picture-delay-ms), declared once for every
// program that plays a site's voice with its pictures: holoport-client and
// holoport-bench live.
#pragma once

#include <string>

#include <CLI/CLI.hpp>

#include "audio/av_sync.h"

namespace holo::net {

// Adds the options to `app`; they write into `sync` (which must outlive the
// parse), and its values are the defaults shown.
inline void AddAvSyncOptions(CLI::App& app, audio::AvSyncOptions* sync) {
  app.add_option_function<std::string>(
         "--av-sync", [sync](const std::string& v) { sync->enabled = v == "on"; },
         "play the site's voices and show its pictures so that what was captured at the same instant is heard "
         "and seen together (the stream that arrives first waits for the other): on, or off (each as soon as it "
         "can; the offset is still measured and reported)")
      ->default_str(sync->enabled ? "on" : "off")
      ->check(CLI::IsMember({"on", "off"}));
  app.add_option_function<std::string>(
         "--hold-pictures", [sync](const std::string& v) { sync->hold_pictures = v == "on"; },
         "lip sync: on (the voice waits until 90 % of the pictures are there and each earlier picture waits for "
         "its voice: in sync even when picture delays spread, for that much more picture delay) or off (pictures "
         "wait only for a slower voice; the voice follows their median)")
      ->default_str(sync->hold_pictures ? "on" : "off")
      ->check(CLI::IsMember({"on", "off"}));
  app.add_option("--max-voice-delay-ms", sync->max_voice_delay_ms,
                 "lip sync: the voice waits at most this long for a later picture (beyond, it leads the picture)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 10000.0));
  app.add_option("--max-picture-delay-ms", sync->max_picture_delay_ms,
                 "lip sync: a picture waits at most this long for a later voice (beyond, the voice lags)")
      ->capture_default_str()
      ->check(CLI::Range(0.0, 10000.0));
}

}  // namespace holo::net
