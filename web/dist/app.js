// fuse1090's live map. It polls the daemon's own documents, the same ones
// tar1090 reads (data/aircraft.json, data/receiver.json) and fuse1090's
// data/receivers.json and data/map.json, and draws them with Leaflet. Every
// URL is relative, so the page also works behind a reverse proxy under a
// sub-path. Nothing is fetched from the internet unless the operator
// configured a tile URL ([http] map_tiles): the coastlines and borders come
// with the page (world.json).
//
// One render per aircraft.json: markers, trails, uncertainty ellipses and
// conflict lines are brought up to date, and aircraft that left the document
// are removed, so what is drawn is exactly what the document holds.
'use strict';
(() => {
  const REFRESH_MS = 1000;
  const RECEIVERS_EVERY = 10; // refreshes between two reads of receivers.json
  const TRAIL_POINTS = 150;
  const ELLIPSE_ZOOM = 12; // the 95% ellipse is drawn from this zoom in
  const STALE_S = 15; // a position older than this is drawn faded
  const K95 = Math.sqrt(5.991); // the 95% contour of a 2-D Gaussian, in sigmas
  const EARTH_M = 6378137;
  const DEG = 180 / Math.PI;
  const COLOURS = { adsb: '#1f6feb', mlat: '#e8590c', fused: '#8e44ad' };
  const PLANE = 'M0,-10 L2,-3 L9,2 L9,4 L2,2 L1.5,7 L4,9 L4,10 L0,9 L-4,10 L-4,9 L-1.5,7 L-2,2 L-9,4 L-9,2 L-2,-3 Z';

  const map = L.map('map', { worldCopyJump: true, zoomSnap: 0.5 }).setView([20, 0], 2);
  map.attributionControl.setPrefix('fuse1090 · Leaflet · Natural Earth');
  const canvas = L.canvas({ padding: 0.2 });
  const layer = () => L.layerGroup().addTo(map);
  const layers = { trails: layer(), ellipses: layer(), conflicts: layer(), receivers: layer(), aircraft: layer() };

  const planes = new Map(); // hex -> { ac, marker, iconKey, trail, trailLine }
  let doc = null; // the aircraft.json drawn last
  let selected = null;
  let sortKey = 'alt';
  let sortDir = -1;
  let fitted = false;
  let refreshes = 0;
  let receivers = [];

  const summary = document.getElementById('summary');
  const details = document.getElementById('details');
  const tbody = document.querySelector('#table tbody');

  // ---- what an aircraft is ------------------------------------------------

  const esc = (s) => String(s).replace(/[&<>"']/g, (c) => `&#${c.charCodeAt(0)};`);
  const callsign = (ac) => (ac.flight || '').trim() || ac.hex;
  const own = (ac) => ac.fuse1090 || {};
  const hasPos = (ac) => typeof ac.lat === 'number' && typeof ac.lon === 'number';
  const age = (ac) => (typeof ac.seen_pos === 'number' ? ac.seen_pos : ac.seen);

  // ADS-B alone, MLAT alone, or both fused into one track.
  function source(ac) {
    const s = own(ac).sources || [];
    const adsb = s.includes('adsb');
    const mlat = s.includes('mlat') || ac.type === 'mlat';
    return adsb && mlat ? 'fused' : mlat ? 'mlat' : 'adsb';
  }

  function altText(ac) {
    if (ac.alt_baro === 'ground') return 'ground';
    const alt = typeof ac.alt_baro === 'number' ? ac.alt_baro : ac.alt_geom;
    return typeof alt === 'number' ? `${alt} ft` : '';
  }

  function sortValue(ac, key) {
    switch (key) {
      case 'hex': return ac.hex;
      case 'flight': return callsign(ac);
      case 'alt': return ac.alt_baro === 'ground' ? -1e9 : (ac.alt_baro ?? ac.alt_geom ?? -2e9);
      case 'gs': return ac.gs ?? -1;
      case 'src': return source(ac);
      case 'h95': return own(ac).h95_m ?? 1e12;
      case 'age': return age(ac) ?? 1e12;
    }
    return 0;
  }

  // ---- drawing -------------------------------------------------------------

  function icon(ac) {
    const shape = typeof ac.track === 'number'
      ? `<path d="${PLANE}" transform="rotate(${ac.track})"/>`
      : '<circle r="5"/>';
    const classes = ['ac', `ac-${source(ac)}`];
    if (own(ac).adsb_suspect) classes.push('suspect');
    if ((age(ac) ?? 0) > STALE_S) classes.push('stale');
    if (ac.hex === selected) classes.push('selected');
    return L.divIcon({
      className: classes.join(' '),
      html: `<svg viewBox="-10 -10 20 20" width="20" height="20">${shape}</svg>`
        + `<span class="label">${esc(callsign(ac))}<br>${esc(altText(ac))}</span>`,
      iconSize: [20, 20],
      iconAnchor: [10, 10],
    });
  }

  // What the icon shows; it is rebuilt only when this changes.
  const iconKey = (ac) => [source(ac), ac.track, callsign(ac), altText(ac), own(ac).adsb_suspect,
    (age(ac) ?? 0) > STALE_S, ac.hex === selected].join('|');

  function drawAircraft(ac) {
    let p = planes.get(ac.hex);
    const at = [ac.lat, ac.lon];
    if (!p) {
      const marker = L.marker(at, { keyboard: false });
      marker.on('click', (e) => { L.DomEvent.stopPropagation(e); select(ac.hex); });
      p = { marker, iconKey: null, trail: [], trailLine: null };
      planes.set(ac.hex, p);
      marker.setIcon(icon(ac));
      marker.addTo(layers.aircraft);
    } else {
      p.marker.setLatLng(at);
    }
    p.ac = ac;
    const key = iconKey(ac);
    if (key !== p.iconKey) {
      p.marker.setIcon(icon(ac));
      p.iconKey = key;
    }
    p.marker.getElement().dataset.hex = ac.hex;
    p.marker.setZIndexOffset(ac.hex === selected ? 1000 : 0);

    const last = p.trail[p.trail.length - 1];
    if (!last || last[0] !== at[0] || last[1] !== at[1]) {
      p.trail.push(at);
      if (p.trail.length > TRAIL_POINTS) p.trail.shift();
    }
    const colour = COLOURS[source(ac)];
    if (!p.trailLine) {
      p.trailLine = L.polyline(p.trail, { color: colour, weight: 2, opacity: 0.55, interactive: false, renderer: canvas });
      p.trailLine.addTo(layers.trails);
    } else {
      p.trailLine.setLatLngs(p.trail);
      p.trailLine.setStyle({ color: colour });
    }
  }

  function removeAircraft(hex) {
    const p = planes.get(hex);
    layers.aircraft.removeLayer(p.marker);
    if (p.trailLine) layers.trails.removeLayer(p.trailLine);
    planes.delete(hex);
  }

  // The 95% contour of the horizontal covariance (east/north, m²), as
  // latitude/longitude points: a local plane is exact enough at these sizes.
  function ellipse(ac) {
    const cov = own(ac).cov_en;
    if (!cov) return null;
    const [[ee, en], [, nn]] = cov;
    const half = (ee + nn) / 2;
    const disc = Math.sqrt(Math.max(half * half - (ee * nn - en * en), 0));
    const a = K95 * Math.sqrt(Math.max(half + disc, 0));
    const b = K95 * Math.sqrt(Math.max(half - disc, 0));
    const theta = 0.5 * Math.atan2(2 * en, ee - nn); // the major axis, from east
    const mPerDegLon = (EARTH_M * Math.cos(ac.lat / DEG)) / DEG;
    const points = [];
    for (let i = 0; i < 40; i++) {
      const t = (i / 40) * 2 * Math.PI;
      const x = a * Math.cos(t);
      const y = b * Math.sin(t);
      const e = x * Math.cos(theta) - y * Math.sin(theta);
      const n = x * Math.sin(theta) + y * Math.cos(theta);
      points.push([ac.lat + (n / EARTH_M) * DEG, ac.lon + e / mPerDegLon]);
    }
    return points;
  }

  function drawOverlays() {
    layers.ellipses.clearLayers();
    layers.conflicts.clearLayers();
    if (!doc) return;
    const zoomedIn = map.getZoom() >= ELLIPSE_ZOOM;
    let ellipses = 0;
    for (const ac of doc.aircraft) {
      if (!hasPos(ac)) continue;
      if (zoomedIn) {
        const pts = ellipse(ac);
        if (pts) {
          L.polygon(pts, { color: COLOURS[source(ac)], weight: 1, fillOpacity: 0.12, interactive: false, renderer: canvas })
            .addTo(layers.ellipses);
          ellipses += 1;
        }
      }
      // A conflict pair is joined once, from the lower address.
      for (const other of own(ac).conflicts || []) {
        const o = planes.get(other);
        if (other > ac.hex && o && hasPos(o.ac)) {
          L.polyline([[ac.lat, ac.lon], [o.ac.lat, o.ac.lon]], { color: '#d00000', weight: 2, dashArray: '6 4', interactive: false })
            .addTo(layers.conflicts);
        }
      }
    }
    // Drawn on a canvas, where no element shows them: counted for checks.
    document.body.dataset.ellipses = ellipses;
  }

  function drawReceivers() {
    layers.receivers.clearLayers();
    for (const r of receivers) {
      const state = r.mlat && r.mlat.state ? ` · ${r.mlat.state}` : '';
      const m = L.marker([r.lat, r.lon], {
        keyboard: false,
        icon: L.divIcon({ className: r.revoked ? 'receiver revoked' : 'receiver', iconSize: [9, 9] }),
      });
      m.bindTooltip(`${esc(r.id)} · ${esc(r.clock)} · ${r.frames_per_s} frames/s${esc(state)}`);
      m.addTo(layers.receivers);
    }
  }

  // ---- the side panel ------------------------------------------------------

  function drawTable() {
    const rows = doc.aircraft.slice().sort((x, y) => {
      const a = sortValue(x, sortKey);
      const b = sortValue(y, sortKey);
      return (a < b ? -1 : a > b ? 1 : x.hex < y.hex ? -1 : 1) * sortDir;
    });
    tbody.innerHTML = rows.map((ac) => {
      const src = source(ac);
      const cls = [ac.hex === selected ? 'selected' : '', own(ac).adsb_suspect ? 'suspect' : ''].join(' ');
      return `<tr data-hex="${esc(ac.hex)}" class="${cls}">`
        + `<td>${esc(ac.hex)}</td><td>${esc((ac.flight || '').trim())}</td>`
        + `<td class="num">${esc(ac.alt_baro ?? '')}</td><td class="num">${ac.gs ?? ''}</td>`
        + `<td class="src-${src}">${src}</td><td class="num">${own(ac).h95_m ?? ''}</td>`
        + `<td class="num">${age(ac) != null ? age(ac).toFixed(1) : ''}</td></tr>`;
    }).join('');
    for (const th of document.querySelectorAll('#table th')) {
      const sorted = th.dataset.key === sortKey;
      th.classList.toggle('sorted', sorted);
      th.classList.toggle('up', sorted && sortDir > 0);
      th.classList.toggle('down', sorted && sortDir < 0);
    }
  }

  function drawDetails() {
    if (!selected) {
      details.hidden = true;
      return;
    }
    details.hidden = false;
    const p = planes.get(selected);
    const ac = p ? p.ac : doc && doc.aircraft.find((a) => a.hex === selected);
    if (!ac) {
      details.innerHTML = `<h2>${esc(selected)}</h2><p>no longer tracked</p>`;
      return;
    }
    const o = own(ac);
    const rows = [
      ['hex', ac.hex], ['flight', (ac.flight || '').trim()], ['squawk', ac.squawk],
      ['source', `${source(ac)} (${(o.sources || []).join(', ')})`], ['track id', o.id],
      ['altitude', altText(ac)], ['geometric alt', ac.alt_geom != null ? `${ac.alt_geom} ft` : null],
      ['vertical rate', ac.geom_rate != null ? `${ac.geom_rate} ft/min` : null],
      ['ground speed', ac.gs != null ? `${ac.gs} kt` : null], ['track', ac.track != null ? `${ac.track}°` : null],
      ['position', hasPos(ac) ? `${ac.lat.toFixed(5)}, ${ac.lon.toFixed(5)}` : null],
      ['95% radius', o.h95_m != null ? `${o.h95_m} m` : null], ['NACp', ac.nac_p],
      ['velocity σ', o.vel_sigma_ms != null ? `${o.vel_sigma_ms} m/s` : null],
      ['motion', o.motion], ['period', o.period_s != null ? `${o.period_s} s` : null],
      ['ADS-B suspect', o.adsb_suspect ? 'yes: timing contradicts its position' : 'no'],
      ['conflicts', (o.conflicts || []).join(', ') || null],
      ['MLAT fields', (ac.mlat || []).join(', ') || null],
      ['seen', ac.seen != null ? `${ac.seen} s ago` : null],
      ['position seen', ac.seen_pos != null ? `${ac.seen_pos} s ago` : null],
    ].filter(([, v]) => v !== null && v !== undefined && v !== '');
    details.innerHTML = `<h2>${esc(callsign(ac))}</h2><dl>`
      + rows.map(([k, v]) => `<dt>${esc(k)}</dt><dd data-field="${esc(k)}">${esc(v)}</dd>`).join('')
      + '</dl>';
  }

  function select(hex) {
    selected = hex;
    const p = planes.get(hex);
    if (p) {
      p.marker.setIcon(icon(p.ac));
      p.iconKey = null;
    }
    if (doc) render(doc);
  }

  // ---- one refresh ---------------------------------------------------------

  function render(d) {
    doc = d;
    const seen = new Set();
    for (const ac of d.aircraft) {
      if (!hasPos(ac)) continue;
      seen.add(ac.hex);
      drawAircraft(ac);
    }
    for (const hex of [...planes.keys()]) if (!seen.has(hex)) removeAircraft(hex);
    drawOverlays();
    drawTable();
    drawDetails();
    const shown = seen.size;
    summary.className = '';
    summary.textContent = `${d.aircraft.length} aircraft, ${shown} on the map · ${receivers.length} receivers`;
    // The document drawn, for whoever checks the page against it.
    document.body.dataset.now = d.now;
    document.body.dataset.drawn = shown;
    if (!fitted && shown > 0) fit();
  }

  function fit() {
    const pts = receivers.map((r) => [r.lat, r.lon]);
    for (const p of planes.values()) pts.push([p.ac.lat, p.ac.lon]);
    if (pts.length === 0) return;
    map.fitBounds(L.latLngBounds(pts), { padding: [30, 30], maxZoom: 14 });
    fitted = true;
  }

  async function getJson(path) {
    const r = await fetch(path, { cache: 'no-store' });
    if (!r.ok) throw new Error(`${path}: HTTP ${r.status}`);
    return r.json();
  }

  async function poll() {
    try {
      if (refreshes % RECEIVERS_EVERY === 0) {
        receivers = (await getJson('data/receivers.json')).receivers || [];
        drawReceivers();
      }
      render(await getJson('data/aircraft.json'));
    } catch (e) {
      summary.className = 'error';
      summary.textContent = `no data from the daemon (${e.message}); retrying`;
    }
    refreshes += 1;
    setTimeout(poll, REFRESH_MS);
  }

  async function start() {
    try {
      const cfg = await getJson('data/map.json');
      if (cfg.tiles) {
        L.tileLayer(cfg.tiles, { attribution: cfg.attribution || '', maxZoom: 19 }).addTo(map);
      }
    } catch (e) {
      // No tile layer: the shipped coastlines are enough.
    }
    try {
      const rx = await getJson('data/receiver.json');
      if (typeof rx.lat === 'number') map.setView([rx.lat, rx.lon], 9);
    } catch (e) {
      // The first aircraft.json fits the view instead.
    }
    getJson('world.json').then((world) => {
      L.geoJSON(world, {
        renderer: canvas,
        interactive: false,
        style: (f) => (f.properties.kind === 'coast'
          ? { color: '#6b7d8f', weight: 1 }
          : { color: '#a3adb8', weight: 1, dashArray: '4 3' }),
      }).addTo(map).bringToBack();
    }).catch(() => {});
    poll();
  }

  document.querySelector('#table thead').addEventListener('click', (e) => {
    const key = e.target.dataset && e.target.dataset.key;
    if (!key) return;
    sortDir = key === sortKey ? -sortDir : 1;
    sortKey = key;
    if (doc) drawTable();
  });
  tbody.addEventListener('click', (e) => {
    const tr = e.target.closest('tr');
    if (!tr) return;
    select(tr.dataset.hex);
    const p = planes.get(tr.dataset.hex);
    if (p) map.panTo(p.marker.getLatLng());
  });
  map.on('click', () => select(null));
  map.on('zoomend', drawOverlays);
  document.addEventListener('keydown', (e) => { if (e.key === 'Escape') select(null); });

  start();
})();
