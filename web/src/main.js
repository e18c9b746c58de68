// The Holoport broadcast viewer page: plays a live broadcast from an edge
// (docs/broadcast.md) — geometry and colour decoded here, the person drawn
// with three.js (WebGL2), the site's voice placed in space with Web Audio's
// HRTF panner, WebXR's immersive mode offered where the browser has it.
//
// Query parameters:
//   src=URL          the broadcast's live.json at an edge (required; its query
//                    string, e.g. a signature, is added to every request)
//   color=vertex|projective   how the person is coloured (default projective)
//   cam=ex,ey,ez,tx,ty,tz     initial camera eye and target (world, Z up)
//   hfov=DEG         horizontal field of view (default 50)
//   freeze=K         stop at frame K and keep showing it (tests, stills)
//   overlay=0        hide the statistics overlay
//   stall_ms=MS      silence after which the edge counts as stalled (3000)

import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
import { VRButton } from 'three/examples/jsm/webxr/VRButton.js';
import { decodeGeometry } from './geometry.js';
import { decodeColor } from './color.js';
import { VideoColorStream } from './video.js';
import { MSG, parseRig, parseMeshFrame, parseColorFrame, parseAudioPose, parseRecords } from './protocol.js';
import { applyNativeProjection } from './view.js';
import { PersonRenderer } from './person.js';
import { SpatialVoice } from './voice.js';

THREE.ColorManagement.enabled = false;

const params = new URLSearchParams(location.search);
const state = {
  status: 'starting', problem: '', framesShown: 0, frameIndex: -1, frozen: false, passEnds: [],
  latencyMs: null, bufferMs: 0, fps: 0, geometryMs: [], colorMs: [], triangles: 0,
  bytes: 0, parts: 0, errors: 0, bufferGrowths: 0, problems: [], audioChunks: 0, mode: '', videoFlushes: 0,
};
window.holoport = {
  state,
  // Stop at frame k (the first frame ≥ k whose colour can be decoded) and
  // keep showing it.
  freezeAt(k) {
    freezeAt = k;
    keepEveryPicture();
  },
};
let freezeAt = params.get('freeze') === null ? null : Number(params.get('freeze'));
// A still needs its frame's colour: its V1 streams never leave pictures
// undecoded to catch up (VideoColorStream's maxInDecoderMs), and the still
// waits for a frame every stream can decode (after a key frame, where one
// had caught up).
function keepEveryPicture() {
  for (const v of videoStreams.values()) v.maxInDecoderMs = Infinity;
}
function videoColourDecodable() {
  for (const v of videoStreams.values()) if (!v.synced) return false;
  return true;
}

const overlayEl = document.getElementById('overlay');
const statusEl = document.getElementById('status');
if (params.get('overlay') === '0') overlayEl.style.display = 'none';

// A message stays up at least 3 s, so that a viewer can read it even when
// the player recovers at once.
let shownAt = 0, clearTimer = null;
function showStatus(level, text) {
  clearTimeout(clearTimer);
  if (!text) {
    const left = 3000 - (performance.now() - shownAt);
    if (left > 0 && state.problem) {
      clearTimer = setTimeout(() => showStatus(level, ''), left);
      return;
    }
  } else {
    shownAt = performance.now();
    state.problems.push({ t: shownAt, level, text });
  }
  state.problem = text;
  statusEl.textContent = text;
  statusEl.className = text ? `visible ${level}` : '';
}

// ---------------------------------------------------------------- rendering

const canvas = document.getElementById('view');
const renderer = new THREE.WebGLRenderer({ canvas, antialias: false, preserveDrawingBuffer: true });
renderer.outputColorSpace = THREE.LinearSRGBColorSpace;
renderer.setPixelRatio(1);
renderer.setClearColor(new THREE.Color(24 / 255, 26 / 255, 30 / 255), 1);
const scene = new THREE.Scene();
const content = new THREE.Group();  // the remote room (Z up); turned Y-up in XR
scene.add(content);
const camera = new THREE.PerspectiveCamera(40, 16 / 9, 0.02, 100);
camera.up.set(0, 0, 1);
const hfov = Number(params.get('hfov') || 50);
const cam = (params.get('cam') || '2.2,-1.6,1.6,0,0,1').split(',').map(Number);
camera.position.set(cam[0], cam[1], cam[2]);
const controls = new OrbitControls(camera, canvas);
controls.target.set(cam[3], cam[4], cam[5]);
controls.update();
const person = new PersonRenderer(content, params.get('color') || 'projective');
window.holoport.view = { renderer, scene, camera, person, controls };
state.mode = person.mode;

function resize() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== w || canvas.height !== h) renderer.setSize(w, h, false);
}

// WebXR: offered where the browser has an immersive mode.
renderer.xr.enabled = true;
if (navigator.xr) {
  navigator.xr.isSessionSupported('immersive-vr').then((ok) => {
    if (ok) document.body.appendChild(VRButton.createButton(renderer));
  }).catch(() => {});
  renderer.xr.addEventListener('sessionstart', () => content.rotation.set(-Math.PI / 2, 0, 0));
  renderer.xr.addEventListener('sessionend', () => content.rotation.set(0, 0, 0));
}

// ---------------------------------------------------------------- decoding

const decodeJpegBitmap = async (bytes) => {
  const bitmap = await createImageBitmap(new Blob([bytes], { type: 'image/jpeg' }),
    { colorSpaceConversion: 'none', premultiplyAlpha: 'none' });
  const c = new OffscreenCanvas(bitmap.width, bitmap.height);
  const g = c.getContext('2d', { willReadFrequently: true });
  g.drawImage(bitmap, 0, 0);
  bitmap.close();
  return g.getImageData(0, 0, c.width, c.height, { colorSpace: 'srgb' });
};

// The same through WebCodecs' ImageDecoder (where the browser has it).
const decodeJpegWebCodecs = async (bytes) => {
  const dec = new ImageDecoder({ data: bytes, type: 'image/jpeg', colorSpaceConversion: 'none' });
  const { image } = await dec.decode();
  const data = new Uint8Array(image.displayWidth * image.displayHeight * 4);
  await image.copyTo(data, { format: 'RGBA' });
  const out = { width: image.displayWidth, height: image.displayHeight, data };
  image.close();
  dec.close();
  return out;
};

// A V1 ColorFrame's pictures, each pod's through its stream in `streams`
// (pod id → VideoColorStream, made on first use).
function decodeVideoFrame(streams, cf) {
  return Promise.all(cf.images.map((im) => {
    if (!streams.has(im.podId)) {
      streams.set(im.podId, new VideoColorStream(freezeAt !== null ? { maxInDecoderMs: Infinity } : {}));
    }
    return streams.get(im.podId).decode(im.data);
  }));
}

// Decode timing in this browser with rendering stopped: every MeshFrame and
// ColorFrame of the given parts (URLs), medians per frame.
window.holoport.benchmark = async (urls) => {
  renderer.setAnimationLoop(null);
  if (window.holoport.live) window.holoport.live.stop();
  const geo = [], col = {}, ways = { bitmap: decodeJpegBitmap };
  if (globalThis.ImageDecoder) ways.imagedecoder = decodeJpegWebCodecs;
  for (const w of Object.keys(ways)) col[w] = [];
  const benchStreams = new Map();
  let videoStalled = false;
  for (const url of urls) {
    const bytes = new Uint8Array(await (await fetch(url)).arrayBuffer());
    for (const m of parseRecords(bytes)) {
      if (m.header.type === MSG.MESH) {
        const t0 = performance.now();
        decodeGeometry(parseMeshFrame(m.payload).data);
        geo.push(performance.now() - t0);
      } else if (m.header.type === MSG.COLOR) {
        const cf = parseColorFrame(m.payload);
        if (cf.codec === 4) {  // V1: WebCodecs' VideoDecoder, the pods' streams in order
          if (videoStalled) continue;
          col.video = col.video || [];
          const t0 = performance.now();
          // A picture that never comes out must not hang the measurement
          // (seen about once in ten runs of the test suite on a loaded
          // 2-core machine): after 10 s the frame counts as stalled, the
          // decoders' states are logged, and the video part stops.
          let timer = null;
          const stalled = new Promise((resolve) => { timer = setTimeout(() => resolve(null), 10000); });
          const images = await Promise.race([decodeVideoFrame(benchStreams, cf), stalled]);
          clearTimeout(timer);
          if (!images) {
            const st = [...benchStreams.entries()].map(([pod, vs]) => `pod ${pod}: ${vs.decoder ? vs.decoder.state : 'none'}, ` +
              `queue ${vs.decoder ? vs.decoder.decodeQueueSize : '-'}, waiting ${vs.waiting.map((w) => w.ts).join(' ') || '-'}`);
            console.error(`benchmark: frame ${cf.frameIndex}'s V1 pictures did not come out in 10 s (${st.join('; ')})`);
            videoStalled = true;
            continue;
          }
          if (images.every((im) => im !== null)) col.video.push(performance.now() - t0);
          continue;
        }
        for (const [w, fn] of Object.entries(ways)) {
          const t0 = performance.now();
          for (const im of cf.images) await decodeColor(im.data, fn);
          col[w].push(performance.now() - t0);
        }
      }
    }
  }
  const med = (a) => (a.length ? [...a].sort((x, y) => x - y)[a.length >> 1] : null);
  const out = { frames: geo.length, geometry_ms_median: med(geo) };
  for (const w of Object.keys(col)) out[`color_ms_median_${w}`] = med(col[w]);
  if (videoStalled) out.video_stalled = true;
  for (const st of benchStreams.values()) st.close();
  return out;
};

// WebCodecs' ImageDecoder where the browser has it (4× faster than
// createImageBitmap + a canvas read-back in Chromium, docs/web.md).
const decodeJpeg = globalThis.ImageDecoder ? decodeJpegWebCodecs : decodeJpegBitmap;

let rig = null;
let rigPayload = null;  // the bytes of the rig in effect
function sameBytes(a, b) {
  if (a.length !== b.length) return false;
  for (let i = 0; i < a.length; ++i) if (a[i] !== b[i]) return false;
  return true;
}
const pending = [];      // messages not yet due: {timeUs, header, payload}
let delayUs = null;      // playhead = (now − availability start) − delayUs
let availStartUs = 0;
let newestShownUs = null;
const voice = new SpatialVoice();
window.holoport.voice = voice;
const colorBusy = { n: 0 };
const videoStreams = new Map();  // pod id → VideoColorStream (V1 colour)

function nowUnixUs() {
  return (performance.timeOrigin + performance.now()) * 1000;
}

function onMessages(messages, info) {
  if (state.frozen) return;  // a still: keep what is shown
  availStartUs = info.availabilityStartUs;
  state.bytes += info.bytes;
  state.parts++;
  const first = messages.length ? messages[0].timeUs : 0;
  if (!messages.length) {
    if (info.discontinuity) person.reset();
    return;
  }
  const broadcastNow = nowUnixUs() - availStartUs;
  // A restart of the stream (discontinuity) takes effect when the playhead
  // reaches it: the frames before it that are still waiting play first (the
  // broadcast's time runs on across a restart). Only a jump in time — ahead
  // of the playhead by more than a second, or back behind what is waiting —
  // drops what is waiting and re-anchors.
  const lastPendingUs = pending.length ? pending[pending.length - 1].timeUs : -Infinity;
  const jump = first > broadcastNow - delayUs + 1e6 || first < lastPendingUs;
  // Join, a jump (catch-up, a skipped segment) or a restart: re-anchor the
  // playhead one part plus 250 ms behind the live edge. A join starts at a
  // segment's first part (its key frame), so the parts up to the edge come
  // due at once: their frames are shown in a burst and their voice, already
  // late, is skipped — the viewer starts at the live edge, not a segment ago.
  if (delayUs === null || jump) {
    const edge = Math.max(first, info.liveEdgeUs || first);
    delayUs = broadcastNow - edge + (info.targetPartUs || 250000) + 250000;
    pending.length = 0;
    if (info.discontinuity) person.reset();
  } else if (info.discontinuity) {
    pending.push({ reset: true, timeUs: first });
  }
  // Parts arriving later than the playhead (a slow network or a busy
  // machine): the buffer grows by the lateness plus 100 ms, so that voice
  // plays (late voice is skipped) and frames are not shown in bursts. The
  // catch-up in pump() bounds the buffer at 4 s.
  const lateUs = broadcastNow - delayUs - messages[messages.length - 1].timeUs;
  if (lateUs > 50000) {
    delayUs += lateUs + 100000;
    state.bufferGrowths++;
  }
  for (const m of messages) {
    // Voice is scheduled on the audio clock as soon as it arrives (ahead of
    // its time by the buffer), so that drawing never delays it.
    if (m.type === MSG.AUDIO) {
      try {
        playVoice(m);
      } catch (e) {
        state.errors++;
      }
    } else {
      pending.push(m);
    }
  }
}

async function handle(m) {
  const t = m.type;
  if (t === MSG.RIG) {
    // A still keeps its rig: each segment starts with the Rig again, and
    // setting it drops the pods' images until the next colour frame.
    if (state.frozen) return;
    // The same rig again (every segment repeats it): nothing changes. Setting
    // it would drop the pods' images every 2 s, and a person whose colour
    // comes less often than that was drawn uncoloured most of the time.
    if (rigPayload && sameBytes(rigPayload, m.payload)) return;
    rig = parseRig(m.payload);
    rigPayload = m.payload.slice();
    person.setRig(rig);
  } else if (t === MSG.MESH) {
    if (state.frozen) return;
    const mf = { frameIndex: m.frameIndex }, mesh = m.mesh;  // decoded in the worker
    state.geometryMs.push(m.decodeMs);
    person.setMesh(mf.frameIndex, mesh);
    state.triangles = mesh.indices.length / 3;
    state.framesShown++;
    state.frameIndex = mf.frameIndex;
    newestShownUs = m.timeUs;
    state.mediaUs = m.timeUs;
    frameTimes.push(performance.now());
    if (freezeAt !== null && mf.frameIndex >= freezeAt && videoColourDecodable()) {
      state.frozen = true;
      state.frozenFrame = mf.frameIndex;
      // A still: nothing more is fetched (its colour frame is already due).
      if (window.holoport.live) window.holoport.live.stop();
      shownAt = 0;
      showStatus('ok', '');
    }
  } else if (t === MSG.COLOR) {
    if (state.frozen && state.frozenFrame !== undefined) {
      const cf0 = parseColorFrame(m.payload);
      if (cf0.frameIndex !== state.frozenFrame) return;
    }
    const cf = parseColorFrame(m.payload);
    // V1 video colour (codec 4): every pod's frames go, in order, to its own
    // WebCodecs decoder (none may be skipped: a delta frame needs the one
    // before); the picture shows once every pod has one.
    if (cf.codec === 4) {
      if (typeof VideoDecoder === 'undefined') {
        if (!state.videoColorNoted) {
          state.videoColorNoted = true;
          showStatus('warn', 'This broadcast sends its colour as V1 video, and this browser has no WebCodecs video decoder: the person is shown uncoloured.');
        }
        return;
      }
      const t0 = performance.now();
      let images;
      try {
        images = await decodeVideoFrame(videoStreams, cf);
      } catch (err) {
        showStatus('warn', `A colour frame could not be decoded (${err.message}); waiting for the next key frame.`);
        return;
      }
      state.videoFlushes = [...videoStreams.values()].reduce((n, v) => n + v.flushes, 0);
      // A pod still waits for its key frame, or newer frames are queued.
      if (!rig || images.some((im) => im === null || im.skipped)) return;
      state.colorMs.push(performance.now() - t0);
      person.setPodImages(cf.frameIndex, cf.images.map((im) => im.podId), images);
      state.colorFrame = person.imagesFrame;
      return;
    }
    // Falling behind: drop colour, never geometry (the still's colour is never dropped).
    if (!rig || (colorBusy.n > 1 && cf.frameIndex !== state.frozenFrame)) return;
    colorBusy.n++;
    const t0 = performance.now();
    try {
      const images = await Promise.all(cf.images.map((im) => decodeColor(im.data, decodeJpeg)));
      state.colorMs.push(performance.now() - t0);
      person.setPodImages(cf.frameIndex, cf.images.map((im) => im.podId), images);
      state.colorFrame = person.imagesFrame;
    } finally {
      colorBusy.n--;
    }
  }
}

function playVoice(m) {
  const a = parseAudioPose(m.payload, m.header);
  state.audioChunks++;
  // A lean frame sent without its pose (every other frame) keeps the last one.
  if (!a.pose) a.pose = state.lastPose || { x: 0, y: 0, z: 0, yaw: 0, pitch: 0, roll: 0 };
  state.lastPose = a.pose;
  const aheadUs = m.timeUs - (nowUnixUs() - availStartUs - delayUs);
  if (aheadUs > -100000) voice.push(a, aheadUs);  // late voice is skipped, never stacked
}

function pump() {
  if (delayUs === null) return;
  const playhead = nowUnixUs() - availStartUs - delayUs;
  // Hold at most a few seconds: beyond that, catch up by skipping ahead.
  if (pending.length && pending[pending.length - 1].timeUs - playhead > 4e6) {
    delayUs -= pending[pending.length - 1].timeUs - playhead - 0.5e6;
  }
  while (pending.length && pending[0].timeUs <= nowUnixUs() - availStartUs - delayUs) {
    const m = pending.shift();
    if (m.reset) {
      if (!state.frozen) {  // a still keeps what it shows
        state.passEnds.push(state.frameIndex);  // the last frame shown before the restart
        person.reset();
      }
      continue;
    }
    handle(m).catch((e) => {
      state.errors++;
      showStatus('warn', `A ${m.type === MSG.COLOR ? 'colour' : 'message'} frame could not be decoded (${e.message}); continuing.`);
      setTimeout(() => { if (state.problem.startsWith('A ')) showStatus('ok', ''); }, 2000);
    });
  }
  state.bufferMs = pending.length ? (pending[pending.length - 1].timeUs - playhead) / 1000 : 0;
  if (newestShownUs !== null) state.latencyMs = (nowUnixUs() - (availStartUs + newestShownUs)) / 1000;
}

// ---------------------------------------------------------------- loop

const frameTimes = [];
function median(a) {
  if (!a.length) return 0;
  const s = [...a].slice(-60).sort((x, y) => x - y);
  return s[s.length >> 1];
}

function updateOverlay() {
  const now = performance.now();
  while (frameTimes.length && now - frameTimes[0] > 2000) frameTimes.shift();
  state.fps = frameTimes.length / 2;
  overlayEl.textContent = [
    `frame ${state.frameIndex}  ${state.fps.toFixed(1)} fps  ${state.triangles} triangles  ${person.mode}`,
    `latency ${state.latencyMs === null ? '–' : (state.latencyMs / 1000).toFixed(2) + ' s'}  buffer ${(state.bufferMs / 1000).toFixed(2)} s`,
    `decode: geometry ${median(state.geometryMs).toFixed(1)} ms  colour ${median(state.colorMs).toFixed(1)} ms`,
    `received ${(state.bytes / 1e6).toFixed(1)} MB in ${state.parts} parts  voice ${voice.enabled ? 'on' : 'off (click)'}`,
  ].join('\n');
}

let lastOverlay = 0;
// Messages are handled on their own timer, so that voice and decoding keep
// time even when drawing is slow.
setInterval(pump, 10);
// Draw only when something changed (a new mesh or colour, the camera, the
// size), or always in XR: an idle page costs nothing, and on a CPU-only
// renderer the decoding and fetching keep their time.
let dirty = true;
controls.addEventListener('change', () => { dirty = true; });
person.onChange = () => { dirty = true; };
renderer.setAnimationLoop(() => {
  state.ticks = (state.ticks || 0) + 1;
  const w = canvas.width, h = canvas.height;
  resize();
  if (w !== canvas.width || h !== canvas.height) dirty = true;
  if (!renderer.xr.isPresenting) {
    controls.update();
    camera.aspect = canvas.width / canvas.height;
    applyNativeProjection(camera, canvas.width, canvas.height, hfov);
    camera.updateMatrixWorld();
  }
  if (dirty || renderer.xr.isPresenting) {
    dirty = false;
    person.prepare(renderer, camera);
    state.renders = (state.renders || 0) + 1;
    renderer.render(scene, camera);
  }
  const xrCam = renderer.xr.isPresenting ? renderer.xr.getCamera() : camera;
  voice.setListener(xrCam, renderer.xr.isPresenting);
  if (performance.now() - lastOverlay > 250) {
    updateOverlay();
    lastOverlay = performance.now();
  }
});

// Voice needs a user gesture in most browsers.
const enableVoice = () => voice.enable();
window.addEventListener('pointerdown', enableVoice, { once: true });
window.addEventListener('keydown', enableVoice, { once: true });
if (params.get('voice') === '1') voice.enable();

// ---------------------------------------------------------------- start

const src = params.get('src');
if (!src) {
  showStatus('error', 'No broadcast given: open this page with ?src=http://EDGE/NAME/live.json');
} else {
  // Fetching, checking and geometry decoding run in a worker (worker.js).
  const worker = new Worker(new URL('./worker.js', import.meta.url), { type: 'module' });
  worker.onmessage = (e) => {
    const m = e.data;
    if (m.kind === 'part') onMessages(m.items, m.info);
    else if (m.kind === 'status') {
      showStatus(m.level, m.text);
      if (m.transient) setTimeout(() => { if (state.problem === m.text) showStatus('ok', ''); }, 3000);
    }
  };
  worker.onerror = (e) => showStatus('error', `Player stopped: ${e.message}`);
  worker.postMessage({ kind: 'start', src: new URL(src, location.href).href, stallMs: Number(params.get('stall_ms') || 3000) });
  window.holoport.live = { stop: () => worker.postMessage({ kind: 'stop' }) };
  state.status = 'playing';
}
