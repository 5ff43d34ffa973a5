// Builds the live map into dist/, which is committed and embedded in the
// fuse1090 binary (src/live/map_assets.rs), so that building fuse1090 needs
// neither npm nor the network. `.ci/run` runs `npm ci && npm run build` and
// fails if dist/ then differs from the commit: the assets are reproducible
// from package-lock.json and src/.
//
// What it does: copies the page (src/), Leaflet's script and style, and
// turns Natural Earth's 1:50m countries (public domain, via world-atlas)
// into two line layers, coastlines and borders, with coordinates rounded to
// 0.01 degree (about 1 km, still finer than the 1:50m data itself) and the
// points that rounding made equal dropped.
import { readFileSync, writeFileSync, mkdirSync, rmSync, copyFileSync } from 'node:fs';
import { mesh } from 'topojson-client';

const dist = new URL('./dist/', import.meta.url);
rmSync(dist, { recursive: true, force: true });
mkdirSync(dist);

const here = (p) => new URL(p, import.meta.url);
for (const f of ['index.html', 'app.js', 'style.css']) copyFileSync(here(`src/${f}`), new URL(f, dist));
copyFileSync(here('node_modules/leaflet/dist/leaflet.js'), new URL('leaflet.js', dist));
copyFileSync(here('node_modules/leaflet/dist/leaflet.css'), new URL('leaflet.css', dist));

const topo = JSON.parse(readFileSync(here('node_modules/world-atlas/countries-50m.json'), 'utf8'));
const round = (x) => Math.round(x * 100) / 100;
const lines = (filter) => {
  const m = mesh(topo, topo.objects.countries, filter);
  return m.coordinates
    .map((line) => line
      .map(([lon, lat]) => [round(lon), round(lat)])
      .filter((p, i, l) => i === 0 || p[0] !== l[i - 1][0] || p[1] !== l[i - 1][1]))
    .filter((line) => line.length > 1);
};
const world = {
  type: 'FeatureCollection',
  features: [
    { type: 'Feature', properties: { kind: 'coast' }, geometry: { type: 'MultiLineString', coordinates: lines((a, b) => a === b) } },
    { type: 'Feature', properties: { kind: 'border' }, geometry: { type: 'MultiLineString', coordinates: lines((a, b) => a !== b) } },
  ],
};
writeFileSync(new URL('world.json', dist), JSON.stringify(world));

const license = (p) => readFileSync(here(p), 'utf8').trim();
writeFileSync(
  new URL('LICENSES.txt', dist),
  [
    'fuse1090 live map: third-party parts',
    '',
    '== leaflet.js, leaflet.css: Leaflet 1.9.4 ==',
    license('node_modules/leaflet/LICENSE'),
    '',
    '== world.json: derived from Natural Earth 1:50m (public domain) through world-atlas 2.0.2 ==',
    license('node_modules/world-atlas/LICENSE'),
    '',
  ].join('\n'),
);
