// holoport-client: the Holoport viewer. Renders the remote site's people
// locally (OpenGL 3.3 core): per-vertex colour or projective texturing from
// the pods' images, free-viewpoint camera, miniature mode, AR compositing
// against local geometry, a K-view mosaic for light-field displays, and an
// overlay with fps, latency, bitrate and drops. The stream is a site server
// (--connect HOST:PORT, or --call CONFIG for one side of a two-site call with
// spatial voice) or the synthetic studio's ground truth (--source).
#include <cstdio>
#include <sstream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "client/net/av_sync_cli.h"
#include "client/offload/offload_main.h"
#include "client/tools/viewer_app.h"
#include "common/log.h"

namespace {

// "X,Y,Z" or "X,Y,Z,YAW" → values; false if malformed.
bool ParseFloats(const std::string& text, std::vector<float>* out) {
  out->clear();
  std::stringstream ss(text);
  std::string item;
  while (std::getline(ss, item, ',')) {
    try {
      size_t used = 0;
      const float v = std::stof(item, &used);
      if (used != item.size()) return false;
      out->push_back(v);
    } catch (...) {
      return false;
    }
  }
  return true;
}

}  // namespace

int main(int argc, char** argv) {
  // Render offload (docs/offload.md): its own command lines.
  for (int i = 1; i < argc; ++i) {
    if (std::string(argv[i]) == "--render-host") return holo::offload::RenderHostMain(argc, argv);
    if (std::string(argv[i]) == "--thin") return holo::offload::ThinClientMain(argc, argv);
  }
  holo::client::ViewerOptions o;
  CLI::App app{
      "holoport-client: the Holoport viewer (local OpenGL rendering of a site's stream).\n"
      "Window controls: left-drag turns, wheel zooms, WASD/E/C move, F orbit/fly, T projective/vertex colour,\n"
      "O overlay, Esc quits."};
  holo::AddLogLevelOption(app);
  app.add_option("--source", o.source,
                 "stream source: synthetic[:WORKLOAD] renders the synthetic studio's ground-truth mesh and pod "
                 "images (workloads S8-QVGA, S8-VGA, S4-QVGA)")
      ->capture_default_str();
  app.add_flag("--headless", o.headless,
               "no window: render --frames frames offscreen (EGL surfaceless, no X server needed) and write PNGs "
               "and stats.json to --out");
  app.add_option("--frames", o.frames, "frames to render (default 30 headless; unlimited in a window)")
      ->check(CLI::Range(0, 1000000));
  app.add_option("--out", o.out_dir, "output folder for PNGs and stats.json")->capture_default_str();
  app.add_option("--width", o.width, "image width")->capture_default_str()->check(CLI::Range(16, 8192));
  app.add_option("--height", o.height, "image height")->capture_default_str()->check(CLI::Range(16, 8192));
  app.add_option("--views", o.views,
                 "K horizontally spaced perspectives per frame, tiled into one mosaic image (light-field display "
                 "input)")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  app.add_option("--view-spacing", o.view_spacing_m, "distance between neighbouring views, metres")
      ->capture_default_str()
      ->check(CLI::Range(0.0f, 1.0f));
  app.add_option("--hfov", o.hfov_deg, "horizontal field of view of each view, degrees")
      ->capture_default_str()
      ->check(CLI::Range(10.0f, 150.0f));
  app.add_option("--color", o.color,
                 "projective (the pods' images blended once per mesh into a texture atlas), projective-fragment "
                 "(blended per pixel, with the view-dependent term; costlier on a CPU GL) or vertex (per-vertex "
                 "colour)")
      ->capture_default_str()
      ->check(CLI::IsMember({"projective", "projective-fragment", "vertex"}));
  app.add_option("--miniature", o.miniature_scale,
                 "miniature mode: scale the remote room by SCALE (e.g. 0.2) onto a table top")
      ->check(CLI::Range(0.01f, 10.0f));
  std::string mini_at;
  app.add_option("--miniature-at", mini_at, "where the remote floor centre goes: X,Y,Z[,YAW_DEG] (default 0,0,0.75)");
  app.add_option("--local", o.local,
                 "local-site geometry for AR compositing (it occludes the remote people): 'table' (a table, the "
                 "default with --miniature), a PLY mesh in local-room coordinates, or synthetic:WORKLOAD (the local "
                 "site's people, live from a second synthetic studio)");
  std::string remote_at, head_at;
  app.add_option("--head-at", head_at,
                 "--call: the participant's head in the own room, X,Y,Z[,YAW_DEG] (default: 2 m in front of the "
                 "room centre, facing it); it is the camera and where the own voice is sent from");
  app.add_option("--remote-at", remote_at,
                 "place the remote room in the local one: X,Y,Z[,YAW_DEG] (e.g. 1.6,0,0,180 puts the remote people "
                 "1.6 m away, facing the local ones)");
  app.add_flag("--see-through", o.see_through,
               "AR see-through: local geometry occludes but is not drawn (the real room shows through)");
  app.add_option("--pose-trace", o.pose_trace,
                 "drive the camera from a head trace CSV (time_s, x, y, z, yaw_deg, pitch_deg, roll_deg); default: "
                 "an orbit around the people");
  app.add_flag("!--no-overlay", o.overlay, "hide the fps/latency/bitrate/drops overlay");
  app.add_flag("!--no-png", o.write_png, "headless: do not write PNGs (stats only)");
  app.add_option("--threads", o.threads, "worker threads of the synthetic source")
      ->capture_default_str()
      ->check(CLI::Range(1, 64));
  app.add_option("--connect", o.connect, "watch the site server at HOST:PORT (instead of --source)");
  app.add_option("--http", o.http,
                 "play a live broadcast from an HTTP edge: http://EDGE/NAME/live.json[?md5=..&expires=..] "
                 "(docs/broadcast.md); --seconds / --frames as with --connect");
  app.add_option("--token", o.token, "viewer token for --connect (default: env HOLO_VIEWER_TOKEN)");
  app.add_option("--quality", o.quality,
                 "--connect/--call: the quality the site may send, 0..10: 10 lets a site with quality layers move "
                 "this viewer between its full and reduced layers by what the link carries; 0..4 keep to the "
                 "reduced layer")
      ->capture_default_str()
      ->check(CLI::Range(0, 10));
  app.add_option("--call", o.call,
                 "one side of a two-site call: call config YAML (docs/sessions.md); watches the remote site, "
                 "publishes the own voice and head pose to the local site, spatializes the remote voices");
  app.add_option("--name", o.name, "participant / client name (shown in the site's log)")->capture_default_str();
  app.add_option("--audio-in", o.audio_in, "--call: own voice, a WAV file (looped; default: a 440 Hz tone)");
  app.add_option("--audio-out", o.audio_out,
                 "--call: write the spatialized remote voices to this stereo WAV; --connect/--http: the site's "
                 "voices as played (mono, in step with the pictures)");
  std::string aec = "off";
  app.add_option("--aec", aec,
                 "--call: echo cancellation and noise suppression of the own voice against the played remote "
                 "voices: on (loudspeakers) or off (headphones)")
      ->capture_default_str()
      ->check(CLI::IsMember({"on", "off"}));
  app.add_option("--aec-filter-ms", o.aec_filter_ms,
                 "--call --aec on: the echo canceller's filter length, ms: 0 = its default (140 ms, rooms up to "
                 "RT60 0.3 s); about 250 for a reverberant room (RT60 0.5 s)")
      ->capture_default_str()
      ->check(CLI::Range(0, 1000));
  app.add_option("--hrtf", o.hrtf_sofa,
                 "--call: a personal HRTF, SOFA file (SimpleFreeFieldHRIR), for the spatialized voices; default: "
                 "OpenAL Soft's built-in set")
      ->check(CLI::ExistingFile);
  holo::net::AddAvSyncOptions(app, &o.sync);
  app.add_option("--delay-voice-ms", o.delay_voice_ms,
                 "test: hold every arriving voice frame this long (a slower voice path)")
      ->check(CLI::Range(0.0, 10000.0));
  app.add_option("--delay-picture-ms", o.delay_picture_ms,
                 "test: hold every decoded picture this long (a slower picture path)")
      ->check(CLI::Range(0.0, 10000.0));
  app.add_option("--seconds", o.seconds, "--connect/--call: stop after this many seconds (0: --frames decides)")
      ->check(CLI::Range(0.0, 1e6));
  app.add_option("--png-every", o.png_every, "headless network run: write every K-th new frame as PNG")
      ->capture_default_str()
      ->check(CLI::Range(1, 1000000));
  app.add_option("--png-interval", o.png_interval_s,
                 "headless network run: write a PNG of the newest frame every S seconds (instead of --png-every)")
      ->check(CLI::Range(0.0, 3600.0));
  app.add_flag("--contact-sheet", o.contact_sheet,
               "headless network run: also write contact_sheet.png (quarter-size tiles of up to 16 written frames)");
  app.add_option("--connect-timeout", o.connect_timeout_s,
                 "give up when the site has not answered within this many seconds (0: wait forever)")
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);
  if (!o.connect.empty() + !o.call.empty() + !o.http.empty() > 1) {
    spdlog::error("holoport-client: give one of --connect, --call and --http");
    return 2;
  }
  o.aec = aec == "on";
  if ((!o.audio_in.empty() || o.aec || !o.hrtf_sofa.empty()) && o.call.empty()) {
    spdlog::error("holoport-client: --audio-in/--aec/--hrtf need --call");
    return 2;
  }
  if (!o.audio_out.empty() && o.call.empty() && o.connect.empty() && o.http.empty()) {
    spdlog::error("holoport-client: --audio-out needs --connect, --http or --call");
    return 2;
  }

  if (!mini_at.empty()) {
    std::vector<float> v;
    if (!ParseFloats(mini_at, &v) || (v.size() != 3 && v.size() != 4)) {
      spdlog::error("holoport-client: --miniature-at: expected X,Y,Z or X,Y,Z,YAW_DEG, got '{}'", mini_at);
      return 2;
    }
    o.miniature_at = Eigen::Vector3f(v[0], v[1], v[2]);
    if (v.size() == 4) o.miniature_yaw_deg = v[3];
    if (o.miniature_scale == 0.0f) {
      spdlog::error("holoport-client: --miniature-at needs --miniature SCALE");
      return 2;
    }
  }
  if (!remote_at.empty()) {
    std::vector<float> v;
    if (!ParseFloats(remote_at, &v) || (v.size() != 3 && v.size() != 4)) {
      spdlog::error("holoport-client: --remote-at: expected X,Y,Z or X,Y,Z,YAW_DEG, got '{}'", remote_at);
      return 2;
    }
    if (o.miniature_scale != 0.0f) {
      spdlog::error("holoport-client: --remote-at and --miniature exclude each other (use --miniature-at)");
      return 2;
    }
    o.remote_placed = true;
    o.remote_at = Eigen::Vector3f(v[0], v[1], v[2]);
    if (v.size() == 4) o.remote_yaw_deg = v[3];
  }
  if (!head_at.empty()) {
    std::vector<float> v;
    if (!ParseFloats(head_at, &v) || (v.size() != 3 && v.size() != 4)) {
      spdlog::error("holoport-client: --head-at: expected X,Y,Z or X,Y,Z,YAW_DEG, got '{}'", head_at);
      return 2;
    }
    if (o.call.empty()) {
      spdlog::error("holoport-client: --head-at needs --call");
      return 2;
    }
    o.head_placed = true;
    o.head_at = Eigen::Vector3f(v[0], v[1], v[2]);
    if (v.size() == 4) o.head_yaw_deg = v[3];
  }
  if (o.miniature_scale != 0.0f && o.local.empty()) o.local = "table";
  return holo::client::RunViewer(o);
}
