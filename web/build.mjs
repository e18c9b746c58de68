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
  entryPoints: [join(here, 'src/main.js')],
  bundle: true,
  minify: true,
  format: 'esm',
  target: ['chrome110', 'firefox115', 'safari16'],
  outfile: join(out, 'viewer.js'),
  legalComments: 'eof',
  logLevel: 'warning',
});
copyFileSync(join(here, 'index.html'), join(out, 'index.html'));
const js = statSync(join(out, 'viewer.js')).size, html = statSync(join(out, 'index.html')).size;
console.log(`${out}: viewer.js ${(js / 1024).toFixed(0)} KiB, index.html ${(html / 1024).toFixed(1)} KiB`);
