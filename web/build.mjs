// Builds the page into dist/: index.html and one bundled, minified
// viewer.js (three.js included: the page fetches nothing from anywhere but
// its own origin and the broadcast's edge).
import { build } from 'esbuild';
import { copyFileSync, mkdirSync, statSync } from 'node:fs';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
// Output directory: the first argument, else web/dist.
const out = process.argv[2] ? resolve(process.argv[2]) : join(here, 'dist');
mkdirSync(out, { recursive: true });
await build({
  entryPoints: { viewer: join(here, 'src/main.js'), worker: join(here, 'src/worker.js') },
  bundle: true,
  minify: true,
  format: 'esm',
  target: ['chrome110', 'firefox115', 'safari16'],
  outdir: out,
  legalComments: 'eof',
  logLevel: 'warning',
});
copyFileSync(join(here, 'index.html'), join(out, 'index.html'));
const size = (f) => statSync(join(out, f)).size;
console.log(`${out}: viewer.js ${(size('viewer.js') / 1024).toFixed(0)} KiB, worker.js ${(size('worker.js') / 1024).toFixed(0)} KiB, ` +
  `index.html ${(size('index.html') / 1024).toFixed(1)} KiB`);
