// Checks the live map in a real browser (Debian's chromium, driven by
// playwright-core) against the daemon's own aircraft.json; run by
// tests/live_map.rs as `node web/test/map.mjs BASE_URL SCREENSHOT.png`.
//
// What it asserts, each against the document the page drew (the page writes
// that document's `now` on <body>; the check retries until a fresh fetch of
// aircraft.json has the same `now`, so both sides see one refresh):
// - the aircraft drawn are exactly those with a position, each labelled with
//   its callsign and rotated to its track; the table lists every aircraft;
// - the receivers drawn are those of receivers.json;
// - clicking an aircraft selects it: its details and its table row;
// - clicking a column sorts the table by it;
// - zoomed in, every aircraft with a covariance has its 95% ellipse (the
//   page counts what it drew on its canvas), zoomed out none;
// - alerts are drawn: the demo has none, so the page is then served the
//   same document with one aircraft made ADS-B suspect and two put in
//   conflict (through the browser's request routing), and must ring the one
//   and join the two;
// - the page asks nothing of any host but the daemon (it works offline)
//   and logs no error.
// It prints one JSON line of what it saw and exits non-zero on a failure.
import { chromium } from 'playwright-core';

const [base, shot] = process.argv.slice(2);
const failures = [];
const check = (ok, what) => { if (!ok) failures.push(what); };
const sameSet = (a, b) => a.length === b.length && a.every((x, i) => x === b[i]);

const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  args: ['--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run', '--disable-background-networking',
    '--disable-component-update', '--disable-sync'],
});
try {
  const page = await browser.newPage({ viewport: { width: 1400, height: 860 } });
  const errors = [];
  page.on('pageerror', (e) => errors.push(e.message));
  page.on('console', (m) => { if (m.type() === 'error') errors.push(m.text()); });
  const elsewhere = [];
  page.on('request', (r) => { if (!r.url().startsWith(`${base}/`) && !r.url().startsWith('data:')) elsewhere.push(r.url()); });
  await page.goto(`${base}/`);
  await page.waitForFunction(() => Number(document.body.dataset.drawn) > 0, null, { timeout: 30000 });

  // One refresh seen by both the page and a fresh fetch.
  const snapshot = () => page.evaluate(async () => {
    const now = document.body.dataset.now;
    const markers = [...document.querySelectorAll('.leaflet-marker-pane .ac[data-hex]')].map((e) => ({
      hex: e.dataset.hex,
      label: e.querySelector('.label').textContent,
      rotate: e.querySelector('path') ? e.querySelector('path').getAttribute('transform') : null,
    }));
    const rows = [...document.querySelectorAll('#table tbody tr')].map((e) => e.dataset.hex);
    const doc = await (await fetch('data/aircraft.json', { cache: 'no-store' })).json();
    return { now, markers, rows, doc };
  });
  let s = null;
  for (let i = 0; i < 40; i++) {
    s = await snapshot();
    if (String(s.doc.now) === s.now) break;
    s = null;
    await page.waitForTimeout(100);
  }
  check(s !== null, 'never saw the page and a fetch on the same refresh');
  if (s) {
    const positioned = s.doc.aircraft.filter((a) => typeof a.lat === 'number');
    const drawn = s.markers.map((m) => m.hex).sort();
    check(sameSet(drawn, positioned.map((a) => a.hex).sort()),
      `drawn ${drawn} but aircraft.json has positions for ${positioned.map((a) => a.hex).sort()}`);
    check(sameSet(s.rows.slice().sort(), s.doc.aircraft.map((a) => a.hex).sort()), 'the table does not list every aircraft');
    for (const a of positioned) {
      const m = s.markers.find((x) => x.hex === a.hex);
      if (!m) continue;
      const name = (a.flight || '').trim() || a.hex;
      check(m.label.startsWith(name), `${a.hex} labelled ${m.label}, not ${name}`);
      if (typeof a.track === 'number') check(m.rotate === `rotate(${a.track})`, `${a.hex} rotated ${m.rotate}, track ${a.track}`);
    }
  }

  const rx = await page.evaluate(async () => ({
    drawn: document.querySelectorAll('.leaflet-marker-pane .receiver').length,
    listed: (await (await fetch('data/receivers.json')).json()).receivers.length,
  }));
  check(rx.drawn === rx.listed && rx.listed > 0, `${rx.drawn} receivers drawn, ${rx.listed} listed`);

  // Select the first aircraft with a callsign by clicking its symbol.
  const target = s && s.doc.aircraft.find((a) => typeof a.lat === 'number' && (a.flight || '').trim());
  let selected = null;
  if (target) {
    await page.click(`.leaflet-marker-pane .ac[data-hex="${target.hex}"] svg`, { force: true });
    await page.waitForSelector('#details:not([hidden]) dd[data-field="hex"]', { timeout: 5000 });
    selected = await page.evaluate(() => ({
      title: document.querySelector('#details h2').textContent,
      hex: document.querySelector('#details dd[data-field="hex"]').textContent,
      row: document.querySelector('#table tbody tr.selected')?.dataset.hex,
      marker: document.querySelector('.leaflet-marker-pane .ac.selected')?.dataset.hex,
    }));
    check(selected.hex === target.hex && selected.title === target.flight.trim(),
      `clicked ${target.hex} (${target.flight.trim()}), details show ${selected.hex} (${selected.title})`);
    check(selected.row === target.hex && selected.marker === target.hex, `the selection is not highlighted: ${JSON.stringify(selected)}`);
  } else {
    check(false, 'no aircraft with a callsign and a position to select');
  }

  // Sort by address, ascending, then descending.
  await page.click('#table th[data-key="hex"]');
  const up = await page.$$eval('#table tbody tr', (rows) => rows.map((r) => r.dataset.hex));
  await page.click('#table th[data-key="hex"]');
  const down = await page.$$eval('#table tbody tr', (rows) => rows.map((r) => r.dataset.hex));
  check(up.length > 1 && sameSet(up, up.slice().sort()), `not sorted up by hex: ${up}`);
  check(sameSet(down, down.slice().sort().reverse()), `not sorted down by hex: ${down}`);
  // Zoomed in, every aircraft with a position and a covariance gets its
  // 95% ellipse; zoomed out, none.
  // The count and the document it was drawn from, on the same refresh.
  // Up to 15 s: on a loaded machine the page's refresh can trail the
  // server's for seconds, and 4 s once missed every matching moment.
  const ellipses = async () => {
    for (let i = 0; i < 150; i++) {
      const e = await page.evaluate(async () => {
        const now = document.body.dataset.now;
        const drawn = Number(document.body.dataset.ellipses);
        const doc = await (await fetch('data/aircraft.json', { cache: 'no-store' })).json();
        const wanted = doc.aircraft.filter((a) => typeof a.lat === 'number' && a.fuse1090 && a.fuse1090.cov_en).length;
        return { same: String(doc.now) === now, drawn, wanted };
      });
      if (e.same) return e;
      await page.waitForTimeout(100);
    }
    return { same: false, drawn: -1, wanted: -1 };
  };
  const zoom = async (button, times) => {
    for (let i = 0; i < times; i++) {
      await page.click(`.leaflet-control-zoom-${button}`);
      await page.waitForTimeout(350);
    }
    await page.waitForTimeout(1200);
  };
  // From the fitted view (about zoom 12 on the demo) out by three, then in
  // by six, then back.
  await zoom('out', 3);
  const out = await ellipses();
  await zoom('in', 6);
  const inside = await ellipses();
  await zoom('out', 3);
  check(out.same && out.drawn === 0, `zoomed out: ${JSON.stringify(out)}`);
  check(inside.same && inside.drawn === inside.wanted && inside.wanted > 0, `zoomed in: ${JSON.stringify(inside)}`);

  // The screenshot: the demo as it is (before the alerts are made up
  // below), the table sorted by altitude as it opens.
  await page.click('#table th[data-key="alt"]');
  await page.screenshot({ path: shot });

  // Alerts, on a document the test alters.
  if (s) {
    const withPos = s.doc.aircraft.filter((a) => typeof a.lat === 'number');
    const [p, q, r] = withPos.map((a) => a.hex);
    await page.route('**/data/aircraft.json', async (route) => {
      const doc = await (await route.fetch()).json();
      for (const a of doc.aircraft) {
        a.fuse1090 = a.fuse1090 || {};
        if (a.hex === p) a.fuse1090.adsb_suspect = true;
        if (a.hex === q) a.fuse1090.conflicts = [r];
        if (a.hex === r) a.fuse1090.conflicts = [q];
      }
      await route.fulfill({ json: doc });
    });
    await page.waitForSelector(`.leaflet-marker-pane .ac.suspect[data-hex="${p}"]`, { timeout: 5000 });
    const alerts = await page.evaluate(() => ({
      suspects: [...document.querySelectorAll('.leaflet-marker-pane .ac.suspect')].map((e) => e.dataset.hex),
      lines: document.querySelectorAll('.leaflet-overlay-pane path[stroke="#d00000"]').length,
      flagged: [...document.querySelectorAll('#table tr.suspect')].map((e) => e.dataset.hex),
    }));
    check(alerts.suspects.length === 1 && alerts.suspects[0] === p, `suspects drawn: ${alerts.suspects}, made: ${p}`);
    check(alerts.flagged.length === 1 && alerts.flagged[0] === p, `suspects in the table: ${alerts.flagged}`);
    check(alerts.lines === 1, `${alerts.lines} conflict lines for one pair`);
    await page.unroute('**/data/aircraft.json');
  }

  check(errors.length === 0, `page errors: ${errors.join('; ')}`);
  check(elsewhere.length === 0, `requests beyond the daemon: ${elsewhere.join(' ')}`);
  console.log(JSON.stringify({
    aircraft: s ? s.doc.aircraft.length : 0,
    drawn: s ? s.markers.length : 0,
    receivers: rx.drawn,
    selected,
    failures,
  }));
} finally {
  await browser.close();
}
process.exit(failures.length === 0 ? 0 : 1);
