// The player's network side in a Web Worker: polls live.json, fetches and
// checks parts (LiveSource), and decodes every MeshFrame's geometry here, so
// that the page's thread only draws. Posts to the page:
//   {kind: 'part', info, items: [{timeUs, type, mesh?, frameIndex?, decodeMs?, payload?}]}
//   {kind: 'status', level, text}
// where a MeshFrame item carries its decoded mesh (buffers transferred) and
// other messages their payload bytes. A MeshFrame that does not decode is
// reported as {kind: 'status'} and dropped (the next key frame follows).

import { LiveSource } from './live.js';
import { MSG, parseMeshFrame } from './protocol.js';
import { decodeGeometry } from './geometry.js';

let live = null;

self.onmessage = (e) => {
  const m = e.data;
  if (m.kind === 'start') {
    live = new LiveSource(m.src, {
      stallMs: m.stallMs,
      onStatus: ({ level, text }) => self.postMessage({ kind: 'status', level, text }),
      onMessages: (messages, info) => {
        const items = [], transfer = [];
        for (const msg of messages) {
          const t = msg.header.type;
          if (t === MSG.MESH) {
            try {
              const mf = parseMeshFrame(msg.payload);
              const t0 = performance.now();
              const mesh = decodeGeometry(mf.data);
              items.push({ timeUs: msg.timeUs, type: t, frameIndex: mf.frameIndex, mesh, decodeMs: performance.now() - t0 });
              for (const a of [mesh.positions, mesh.normals, mesh.colors, mesh.indices]) if (a) transfer.push(a.buffer);
            } catch (err) {
              self.postMessage({ kind: 'status', level: 'warn', text: `A geometry frame could not be decoded (${err.message}); continuing.`, transient: true });
            }
          } else {
            const payload = msg.payload.slice();
            items.push({ timeUs: msg.timeUs, type: t, payload });
            transfer.push(payload.buffer);
          }
        }
        self.postMessage({ kind: 'part', info, items }, transfer);
      },
    });
    live.run().catch((err) => self.postMessage({ kind: 'status', level: 'error', text: `Player stopped: ${err.message}` }));
  } else if (m.kind === 'stop' && live) {
    live.stop();
  }
};
