// The browser viewer in a real browser (headless Chromium through
// puppeteer-core), against a local live broadcast: live_server.mjs as the
// origin and an nginx edge with the shipped configuration in front of it
// (scripts/broadcast.sh start --no-origin), so the page gets what a viewer
// gets from an edge: its caching (live.json per cache bucket), CORS headers
// and lock behaviour.
//
//   playback: plays ≥ 5 s from the live edge, freezes a frame, screenshots it
//             from a fixed camera and compares with the native renderer's
//             image of the same frame and camera (holoport-web-fixture
//             render): PSNR ≥ 30 dB.
//   faults:   a damaged part, then a stalled edge: the page shows a message
//             (and keeps rendering), then recovers when data returns.
//
// Usage: node browser_test.mjs playback|faults --recording R --dist DIR
//        [--fixture BIN --out DIR] [--color vertex|projective]
// Exit 0 pass, 1 fail, 77 Chromium cannot start (the reason printed).

import { spawn, execFileSync } from 'node:child_process';
import { readFileSync, writeFileSync, mkdirSync, mkdtempSync, rmSync, statSync } from 'node:fs';
import { createServer } from 'node:net';
import { tmpdir } from 'node:os';
import { join, dirname } from 'node:path';
import { fileURLToPath } from 'node:url';
import puppeteer from 'puppeteer-core';
import { parseRecording, parseMeshFrame, MSG } from '../src/protocol.js';

const here = dirname(fileURLToPath(import.meta.url));
const args = process.argv.slice(2);
const mode = args[0];
function opt(name, def) {
  const i = args.indexOf(name);
  return i >= 0 ? args[i + 1] : def;
}
const known = new Set(['--recording', '--dist', '--fixture', '--out', '--color', '--chromium']);
for (let i = 1; i < args.length; i += 2) {
  if (!known.has(args[i])) {
    console.error(`browser_test: unknown option ${args[i]}`);
    process.exit(2);
  }
}
if (mode !== 'playback' && mode !== 'faults') {
  console.error('usage: node browser_test.mjs playback|faults --recording R --dist DIR [--fixture BIN --out DIR]');
  process.exit(2);
}
const recording = opt('--recording');
const dist = opt('--dist');
const outDir = opt('--out', '/tmp/holoport-web-test');
const color = opt('--color', 'vertex');
const chromium = opt('--chromium', '/usr/bin/chromium');
mkdirSync(outDir, { recursive: true });
const lastFrame = Math.max(...parseRecording(new Uint8Array(readFileSync(recording)))
  .filter((m) => m.header.type === MSG.MESH).map((m) => parseMeshFrame(m.payload).frameIndex));
const W = 640, H = 360, HFOV = 50, EYE = [3.3, -2.4, 1.5], TARGET = [0, 0, 0.9];

let failures = 0;
function check(cond, what) {
  console.log(`${cond ? 'ok' : 'FAIL'}: ${what}`);
  if (!cond) failures++;
}
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
async function waitFor(page, fn, timeoutMs, what, arg) {
  const t0 = Date.now();
  while (Date.now() - t0 < timeoutMs) {
    if (await page.evaluate(fn, arg)) return true;
    await sleep(100);
  }
  console.log(`timed out after ${timeoutMs} ms waiting for ${what}`);
  return false;
}

// ---- the broadcast and the page
const server = spawn(process.execPath, [join(here, 'live_server.mjs'), recording, '--page-dir', dist], {
  stdio: ['ignore', 'pipe', 'inherit'],
});
const urls = await new Promise((resolve, reject) => {
  let buf = '';
  server.stdout.on('data', (d) => {
    buf += d;
    const nl = buf.indexOf('\n');
    if (nl >= 0) resolve(JSON.parse(buf.slice(0, nl)));
  });
  server.on('exit', (code) => reject(new Error(`live_server exited ${code}`)));
});

// ---- an nginx edge in front of it
const broadcastSh = join(here, '..', '..', 'scripts', 'broadcast.sh');
const edgeRun = mkdtempSync(join(tmpdir(), 'holoport-web-edge-'));
function stopEdge() {
  try {
    execFileSync(broadcastSh, ['stop', '--run', edgeRun], { stdio: 'ignore' });
  } catch { /* already gone */ }
  rmSync(edgeRun, { recursive: true, force: true });
}
const freePort = () => new Promise((resolve, reject) => {
  const s = createServer();
  s.on('error', reject);
  s.listen(0, '127.0.0.1', () => {
    const { port } = s.address();
    s.close(() => resolve(port));
  });
});
let edgeUrl;
try {
  const edgePort = await freePort();
  execFileSync(broadcastSh, ['start', '--no-origin', '--run', edgeRun, '--root', edgeRun, '--origin-port',
    new URL(urls.broadcast).port, '--edges', '1', '--edge-port', String(edgePort)], { stdio: ['ignore', 'inherit', 'inherit'] });
  edgeUrl = `http://127.0.0.1:${edgePort}/live/live.json`;
} catch (e) {
  console.log(`FAIL: the nginx edge did not start (scripts/setup.sh installs nginx-light): ${e.message.split('\n')[0]}`);
  server.kill();
  stopEdge();
  process.exit(1);
}
console.log(`broadcast ${urls.broadcast} (origin) through the edge ${edgeUrl}, page ${urls.page}`);

let browser;
try {
  browser = await puppeteer.launch({
    executablePath: chromium,
    headless: true,
    args: ['--headless=new', '--no-sandbox', '--disable-gpu', '--use-gl=angle', '--use-angle=swiftshader',
      '--enable-unsafe-swiftshader', '--autoplay-policy=no-user-gesture-required', `--window-size=${W},${H}`],
    defaultViewport: { width: W, height: H, deviceScaleFactor: 1 },
    timeout: 30000,
  });
} catch (e) {
  console.log(`SKIP: Chromium cannot start (${chromium}): ${e.message.split('\n')[0]}`);
  server.kill();
  stopEdge();
  process.exit(77);
}

const requests = [];
let exitCode = 1;
try {
  const page = await browser.newPage();
  page.on('console', (m) => { if (m.type() === 'error') console.log(`page console: ${m.text()}`); });
  page.on('pageerror', (e) => { console.log(`page error: ${e.message}`); failures++; });
  page.on('request', (r) => requests.push(r.url()));
  const q = new URLSearchParams({
    src: edgeUrl, color, hfov: String(HFOV), cam: [...EYE, ...TARGET].join(','),
    overlay: mode === 'playback' ? '0' : '1', stall_ms: mode === 'playback' ? '5000' : '1500', voice: '1',
  });
  const t0 = Date.now();
  await page.goto(`${urls.page}?${q}`, { waitUntil: 'load' });
  check(await waitFor(page, () => window.holoport && window.holoport.state.framesShown > 0, 30000, 'the first frame'),
    'the page shows a frame from the live edge');
  const firstShownMs = Date.now() - t0;
  const s0 = await page.evaluate(() => ({ ...window.holoport.state }));

  if (mode === 'playback') {
    await sleep(5000);
    const s1 = await page.evaluate(() => ({ ...window.holoport.state }));
    // Functional, not a speed test (the machine may be loaded): frames and
    // broadcast time advance, voice plays, no trouble reported.
    check(s1.framesShown - s0.framesShown >= 10, `played 5 s: ${s1.framesShown - s0.framesShown} frames shown (frame ${s0.frameIndex} → ${s1.frameIndex}; buffer grown ${s1.bufferGrowths}×, now ${(s1.bufferMs / 1000).toFixed(2)} s)`);
    check(s1.mediaUs - s0.mediaUs >= 3e6, `broadcast time advanced ${((s1.mediaUs - s0.mediaUs) / 1e6).toFixed(2)} s in 5 s`);
    check(s1.problems.length === 0, `no problem shown while playing (${s1.problems.map((p) => p.text).join('; ') || 'none'})`);
    // The recording loops (a discontinuity every pass): the frames before a
    // restart play out, none is dropped when the restart arrives. (A join or
    // a grown buffer can leave the 5 s without a restart: wait for one.)
    await waitFor(page, () => window.holoport.state.passEnds.length >= 1, 15000, 'a restart of the looping recording');
    const ends = await page.evaluate(() => [...window.holoport.state.passEnds]);
    check(ends.length >= 1 && ends.every((f) => f === lastFrame),
      `every pass plays to its last frame before the restart (${lastFrame}): last frames shown [${ends.join(', ')}]`);
    check(s1.audioChunks >= 100, `voice: ${s1.audioChunks} AudioPose messages played`);
    const v = await page.evaluate(() => {
      const vo = window.holoport.voice, p = window.holoport.state.lastPose;
      if (!vo.enabled) return null;
      // The positions scheduled for now: the last one at or before the audio
      // clock, and those that fell due in the 250 ms before it (the value an
      // AudioParam reports is that of the last render quantum, which trails
      // the clock on a busy machine). Sorted by time: a late part is
      // scheduled at once, so pushes are not always in time order.
      const t = vo.ctx.currentTime;
      const past = (vo.scheduled || []).filter((e) => e.when <= t).sort((a, b) => a.when - b.when);
      const due = past.filter((e, i) => e.when >= t - 0.25 || i === past.length - 1 || past[i + 1].when >= t - 0.25);
      const x = vo.panner.positionX.value, y = vo.panner.positionY.value, z = vo.panner.positionZ.value;
      const dist = (e) => Math.hypot(x - e.pos[0], y - e.pos[1], z - e.pos[2]);
      const best = due.reduce((b, e) => (!b || dist(e) < dist(b) ? e : b), null);
      const match = best && dist(best) < 0.05 ? best : null;
      return { ctx: vo.ctx.state, model: vo.panner.panningModel, x, y, z,
        due: due.length ? (match || due[due.length - 1]).pos : null, lagMs: match ? (t - match.when) * 1000 : null,
        candidates: due.length, pose: p,
        mapped: (vo.scheduled || []).map((e) => Math.hypot(e.pos[0] - e.pose.x, e.pos[1] - e.pose.z, e.pos[2] + e.pose.y)) };
    });
    check(v && v.ctx === 'running' && v.model === 'HRTF', `voice through an HRTF PannerNode (${JSON.stringify(v && { ctx: v.ctx, model: v.model })})`);
    // The panner follows the heads of the AudioPoses as they play (room Z up → Web Audio Y up).
    check(v && v.due && Math.hypot(v.x - v.due[0], v.y - v.due[1], v.z - v.due[2]) < 0.05,
      `panner at the playing speaker's head: (${v && [v.x, v.y, v.z].map((q) => q.toFixed(2))}), scheduled (${v && v.due && v.due.map((q) => q.toFixed(2))}) ${v && v.lagMs !== null ? `${v.lagMs.toFixed(0)} ms before the audio clock` : `(none of ${v && v.candidates} positions due in the last 250 ms)`}; last pose received (${v && [v.pose.x, v.pose.y, v.pose.z].map((q) => q.toFixed(2))}) → Web Audio (x, z, −y)`);
    check(v && v.mapped.length > 0 && v.mapped.every((d) => d < 1e-6),
      `every scheduled voice position is its AudioPose's head, room (x, y, z) → Web Audio (x, z, −y) (${v && v.mapped.length} checked)`);
    // Freeze a few frames ahead; near the end of the recording's pass (the
    // broadcast loops it), at the first frame of the next pass instead.
    const cur = await page.evaluate(() => window.holoport.state.frameIndex);
    const k = cur + 6 <= lastFrame ? cur + 6 : 0;
    await page.evaluate((kk) => window.holoport.freezeAt(kk), k);
    check(await waitFor(page, () => window.holoport.state.frozen, 20000, 'the frozen frame'), `froze at frame ≥ ${k}`);
    if (color === 'projective') {
      check(await waitFor(page, () => window.holoport.state.colorFrame === window.holoport.state.frozenFrame, 20000,
        'the frozen frame\'s colour images'), 'the frozen frame\'s colour images are shown');
    }
    await sleep(500);  // a few renders
    const s2 = await page.evaluate(() => ({ ...window.holoport.state }));
    const frame = s2.frozenFrame;
    const shot = join(outDir, `web_frame${frame}_${color}.png`);
    await page.screenshot({ path: shot, clip: { x: 0, y: 0, width: W, height: H } });
    const native = join(outDir, `native_frame${frame}_${color}.png`);
    execFileSync(opt('--fixture'), ['render', '--recording', recording, '--frame', String(frame), '--out', native,
      '--eye', EYE.join(','), '--target', TARGET.join(','), '--hfov', String(HFOV), '--width', String(W),
      '--height', String(H), '--color', color], { stdio: 'inherit' });
    // PSNR over all pixels (RGB), both PNGs decoded by the browser.
    const toData = (p) => `data:image/png;base64,${readFileSync(p).toString('base64')}`;
    const psnr = await page.evaluate(async (a, b) => {
      const pixels = async (url) => {
        const bmp = await createImageBitmap(await (await fetch(url)).blob(), { colorSpaceConversion: 'none' });
        const c = new OffscreenCanvas(bmp.width, bmp.height);
        const g = c.getContext('2d');
        g.drawImage(bmp, 0, 0);
        return g.getImageData(0, 0, bmp.width, bmp.height);
      };
      const x = await pixels(a), y = await pixels(b);
      if (x.width !== y.width || x.height !== y.height) return { error: `sizes ${x.width}x${x.height} vs ${y.width}x${y.height}` };
      let se = 0, n = 0, fgSe = 0, fgN = 0;
      for (let i = 0; i < x.data.length; i += 4) {
        let px = 0;
        for (let c = 0; c < 3; ++c) {
          const d = x.data[i + c] - y.data[i + c];
          px += d * d;
        }
        se += px;
        n += 3;
        const bg = (v, j) => v[j] === 24 && v[j + 1] === 26 && v[j + 2] === 30;
        if (!bg(x.data, i) || !bg(y.data, i)) {
          fgSe += px;
          fgN += 3;
        }
      }
      const db = (e, k) => (e === 0 ? 99 : 10 * Math.log10((255 * 255 * k) / e));
      return { psnr: db(se, n), psnr_person: db(fgSe, fgN), person_pixels: fgN / 3 };
    }, toData(shot), toData(native));
    console.log(`screenshot ${shot}, native ${native}`);
    const geoMs = [...s2.geometryMs].sort((a, b) => a - b), colMs = [...s2.colorMs].sort((a, b) => a - b);
    const pageBytes = ['index.html', 'viewer.js', 'worker.js'].reduce((a, f) => a + statSync(join(dist, f)).size, 0);
    console.log(JSON.stringify({
      figure: 'web_vs_native', content: 'truth', frame, color, width: W, height: H, psnr_db: psnr.psnr,
      psnr_person_db: psnr.psnr_person, person_pixels: psnr.person_pixels, first_frame_ms: firstShownMs,
      latency_ms: s1.latencyMs, geometry_decode_ms_median: geoMs[geoMs.length >> 1] ?? null,
      color_decode_ms_median: colMs[colMs.length >> 1] ?? null, triangles: s2.triangles, page_bytes: pageBytes,
      received_bytes: s2.bytes, parts: s2.parts, video_flushes: s2.videoFlushes ?? 0,
    }));
    // Decode time in this browser, rendering stopped: the parts of segment 0.
    const base = edgeUrl.replace(/live\.json$/, '');
    const bench = await page.evaluate((b) => window.holoport.benchmark([0, 1, 2, 3].map((k) => `${b}seg_00000.p${k}`)), base);
    console.log(JSON.stringify({ figure: 'web_decode_browser', content: 'truth', ...bench }));
    check(psnr.psnr >= 30, `PSNR vs native ${psnr.psnr?.toFixed(2)} dB (person pixels: ${psnr.psnr_person?.toFixed(2)} dB) ≥ 30 dB`);
  } else {
    // A damaged part: a message naming it, then recovery at the next segment.
    await fetch(`${urls.control}corrupt`);
    check(await waitFor(page, () => window.holoport.state.problems.some((p) => /damaged/.test(p.text)), 20000, 'the damaged-part message'),
      'a damaged part shows a message');
    const msg1 = await page.evaluate(() => window.holoport.state.problems.map((p) => p.text).find((t) => /damaged/.test(t)));
    console.log(`  message: "${msg1}"`);
    const fBefore = await page.evaluate(() => window.holoport.state.framesShown);
    check(await waitFor(page, (f) => !document.getElementById('status').classList.contains('visible') &&
      window.holoport.state.framesShown > f + 10, 20000, 'recovery after the damaged part', fBefore), 'recovers after the damaged part');
    // A stalled edge: nothing answers for 5 s.
    await fetch(`${urls.control}stall?ms=5000`);
    const rBefore = await page.evaluate(() => window.holoport.state.ticks);
    check(await waitFor(page, () => window.holoport.state.problems.some((p) => /No new data/.test(p.text)), 20000, 'the stall message'),
      'a stalled edge shows a message');
    const msg2 = await page.evaluate(() => window.holoport.state.problems.map((p) => p.text).find((t) => /No new data/.test(t)));
    await page.screenshot({ path: join(outDir, 'web_stalled.png') });
    console.log(`  message: "${msg2}"`);
    const rDuring = await page.evaluate(() => window.holoport.state.ticks);
    check(rDuring > rBefore + 5, `the page stays live while stalled (${rDuring - rBefore} animation frames)`);
    const f2 = await page.evaluate(() => window.holoport.state.framesShown);
    check(await waitFor(page, (f) => !document.getElementById('status').classList.contains('visible') &&
      window.holoport.state.framesShown > f + 10, 20000, 'recovery after the stall', f2), 'recovers after the stall');
    await page.screenshot({ path: join(outDir, 'web_recovered.png') });
  }
  // Only the page's origin and the broadcast's edge were contacted.
  const origins = new Set(requests.filter((u) => u.startsWith('http')).map((u) => new URL(u).origin));
  const allowed = new Set([new URL(urls.page).origin, new URL(edgeUrl).origin]);
  check([...origins].every((o) => allowed.has(o)), `requests only to the page and the edge (${[...origins].join(', ')})`);
  // The manifest went through the edge's cache: polls carried a bucket, and
  // the edge answered some of them from its copy.
  const edgeLog = readFileSync(join(edgeRun, 'edge0', 'access.log'), 'utf8').split('\n');
  const bucketed = edgeLog.filter((l) => /GET \/live\/live\.json\?b=\d+ /.test(l));
  check(bucketed.length > 0, `manifest polls carry a cache bucket (${bucketed.length} at the edge)`);
  const partHits = edgeLog.filter((l) => /GET \/live\/seg_\d+\.p\d+ .* 200 .* (MISS|HIT)$/.test(l)).length;
  check(partHits > 0, `parts came through the edge's cache (${partHits})`);
  exitCode = failures ? 1 : 0;
} catch (e) {
  console.log(`FAIL: ${e.stack || e}`);
  exitCode = 1;
} finally {
  await browser.close();
  server.kill();
  stopEdge();
}
console.log(exitCode ? `${mode}: FAILED` : `${mode}: passed`);
writeFileSync(join(outDir, `${mode}.done`), String(exitCode));
process.exit(exitCode);
