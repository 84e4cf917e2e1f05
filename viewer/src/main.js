// The seqloc viewer: a region's tiles in the region's own Transverse Mercator projection (no Web
// Mercator reprojection: cells stay square and north stays grid north), with a localize track on
// top coloured by each frame's position error (the recall thresholds, as `seqloc render`'s
// overview) or by its entropy, and the ground truth dashed beside it. Everything comes
// from `seqloc serve`: /catalog, a region's tilejson.json (its CRS and tile matrix) and its tiles.
// With ?web=1 the same layers come as the server's Web Mercator XYZ tiles, as in any web map.
// With ?pmtiles=FILE.pmtiles no server is needed: the page, served as static files, shows that
// archive (`seqloc export --format pmtiles`) over Web Mercator, read by HTTP range requests.

import Map from 'ol/Map.js';
import View from 'ol/View.js';
import TileLayer from 'ol/layer/Tile.js';
import VectorLayer from 'ol/layer/Vector.js';
import TileImage from 'ol/source/TileImage.js';
import XYZ from 'ol/source/XYZ.js';
import ScaleLine from 'ol/control/ScaleLine.js';
import MousePosition from 'ol/control/MousePosition.js';
import { defaults as defaultControls } from 'ol/control/defaults.js';
import VectorSource from 'ol/source/Vector.js';
import TileGrid from 'ol/tilegrid/TileGrid.js';
import GeoJSON from 'ol/format/GeoJSON.js';
import DragAndDrop from 'ol/interaction/DragAndDrop.js';
import { defaults as defaultInteractions } from 'ol/interaction/defaults.js';
import { Circle, Fill, Stroke, Style } from 'ol/style.js';
import { register } from 'ol/proj/proj4.js';
import { get as getProjection, toLonLat, transform, transformExtent } from 'ol/proj.js';
import proj4 from 'proj4';
import { PMTilesRasterSource } from 'ol-pmtiles';
import { PMTiles } from 'pmtiles';
import 'ol/ol.css';
import './app.css';

const status = { tilesLoaded: 0, tileErrors: 0, trackPoints: 0, region: null, error: null };
window.seqlocViewer = status;

function showStatus() {
  const s = document.getElementById('status');
  s.textContent = status.error
    ? `error: ${status.error}`
    : `region ${status.region}: ${status.tilesLoaded} tiles loaded, ${status.tileErrors} failed; ` +
      `track: ${status.trackPoints} points`;
  s.dataset.tiles = status.tilesLoaded;
  s.dataset.tileErrors = status.tileErrors;
  s.dataset.trackPoints = status.trackPoints;
}

async function fetchJson(url) {
  const r = await fetch(url);
  if (!r.ok) throw new Error(`${url}: HTTP ${r.status}`);
  return r.json();
}

// Viridis stops, entropy 0 (confident) to 1 (flat).
const VIRIDIS = [[68, 1, 84], [59, 82, 139], [33, 145, 140], [94, 201, 98], [253, 231, 37]];
function viridis(t) {
  t = Math.min(1, Math.max(0, t)) * (VIRIDIS.length - 1);
  const i = Math.min(Math.floor(t), VIRIDIS.length - 2), f = t - i;
  const c = VIRIDIS[i].map((a, k) => Math.round(a + (VIRIDIS[i + 1][k] - a) * f));
  return `rgb(${c[0]},${c[1]},${c[2]})`;
}

const lineStyle = new Style({ stroke: new Stroke({ color: 'rgba(0,0,0,0.7)', width: 2 }) });
// The ground truth (track.geojson's "track": "ground_truth" line), dashed blue beside the estimate.
const truthStyle = new Style({ stroke: new Stroke({ color: 'rgb(30,90,220)', width: 2, lineDash: [6, 4] }) });
// Position error classes: under 1 m, 3 m, 5 m, and 5 m or more, as recall counts them (error < t;
// render.cpp's error_colour).
const ERROR_CLASSES = [[1, 'rgb(26,152,80)'], [3, 'rgb(145,207,96)'], [5, 'rgb(253,174,97)'],
                       [Infinity, 'rgb(215,48,39)']];
function errorColour(e) {
  return ERROR_CLASSES.find(([limit]) => e < limit)[1];
}
let colourBy = 'error';  // or 'entropy'
const pointStyles = new globalThis.Map();
function pointStyle(colour) {
  if (!pointStyles.has(colour)) {
    pointStyles.set(colour, new Style({ image: new Circle({ radius: 5, fill: new Fill({ color: colour }),
                                                            stroke: new Stroke({ color: '#000', width: 1 }) }) }));
  }
  return pointStyles.get(colour);
}
function trackStyle(feature) {
  if (feature.getGeometry().getType() !== 'Point') {
    return feature.get('track') === 'ground_truth' ? truthStyle : lineStyle;
  }
  const value = Number(feature.get(colourBy === 'error' ? 'position_error_m' : 'entropy'));
  if (feature.get(colourBy === 'error' ? 'position_error_m' : 'entropy') === undefined || !Number.isFinite(value)) {
    return pointStyle('#888');
  }
  return pointStyle(colourBy === 'error' ? errorColour(value) : viridis(Math.round(value * 50) / 50));
}

// Shows the legend of the colouring in use.
function setColourBy(mode) {
  colourBy = mode;
  document.getElementById('entropy-legend').hidden = mode !== 'entropy';
  document.getElementById('error-legend').hidden = mode !== 'error';
  trackSource.changed();
}

function tileLayer(region, tj, layer, visible, opacity) {
  const m = tj.tile_matrix;
  const grid = new TileGrid({ origin: m.top_left, extent: m.extent, resolutions: [m.cell_m], tileSize: m.tile_size });
  const source = new TileImage({
    projection: `seqloc:${region}`,
    tileGrid: grid,
    // OpenLayers counts tile rows down from a top-left origin, as the cache does.
    tileUrlFunction: ([, x, y]) => `regions/${region}/${layer}/${x}/${y}.png?style=color`,
    crossOrigin: 'anonymous',
  });
  source.on('tileloadend', () => { status.tilesLoaded++; showStatus(); });
  source.on('tileloaderror', () => { status.tileErrors++; showStatus(); });
  return new TileLayer({ source, visible, opacity });
}

// The server's Web Mercator XYZ tiles of one layer (tilejson's template; zooms from tilejson).
function xyzLayer(tj, layer, visible, opacity) {
  const source = new XYZ({
    url: `${tj.layers[layer].tiles[0]}?style=color`,
    minZoom: tj.minzoom,
    maxZoom: tj.maxzoom,
    crossOrigin: 'anonymous',
  });
  source.on('tileloadend', () => { status.tilesLoaded++; showStatus(); });
  source.on('tileloaderror', () => { status.tileErrors++; showStatus(); });
  return new TileLayer({ source, visible, opacity });
}

const trackSource = new VectorSource();
let map = null;

function addTrack(text, name) {
  const format = new GeoJSON();
  const features = format.readFeatures(text, { dataProjection: 'EPSG:4326',
                                                featureProjection: map.getView().getProjection() });
  trackSource.clear();
  trackSource.addFeatures(features);
  const points = features.filter((f) => f.getGeometry().getType() === 'Point');
  status.trackPoints = points.length;
  // A track without ground truth has no errors to colour by.
  const hasErrors = points.some((f) => f.get('position_error_m') !== undefined);
  const select = document.getElementById('colour-by');
  select.querySelector('option[value=error]').disabled = !hasErrors;
  if (!hasErrors && select.value === 'error') select.value = 'entropy';
  setColourBy(select.value);
  showStatus();
  if (features.length) map.getView().fit(trackSource.getExtent(), { padding: [40, 40, 40, 40], maxZoom: trackMaxZoom });
  document.getElementById('info').textContent = `track ${name}: ${status.trackPoints} frames`;
}

async function loadTrack(url) {
  try {
    const r = await fetch(url);
    if (!r.ok) throw new Error(`HTTP ${r.status}`);
    addTrack(await r.text(), url.startsWith('data:') ? '(inline)' : url);
  } catch (e) {
    status.error = `track ${url.slice(0, 80)}: ${e.message}`;
    showStatus();
  }
}

const webMercator = new URLSearchParams(window.location.search).get('web') === '1';
let regionCode = null;  // the region CRS, for the cursor's region metres
let trackMaxZoom = 4;   // a track is fitted no closer than 0.5 m pixels

// The cursor: lat/lon and region metres, whichever projection the view is in.
function formatCursor(coordinate) {
  if (!coordinate || !map) return '';
  const viewProjection = map.getView().getProjection();
  const [lon, lat] = toLonLat(coordinate, viewProjection);
  const [x, y] = transform(coordinate, viewProjection, regionCode);
  return `${lat.toFixed(6)}, ${lon.toFixed(6)} | x ${x.toFixed(1)} m, y ${y.toFixed(1)} m`;
}

async function showRegion(region) {
  const tj = await fetchJson(`regions/${region}/tilejson.json`);
  const code = `seqloc:${region}`;
  proj4.defs(code, tj.crs.proj);
  register(proj4);
  regionCode = code;
  const projection = getProjection(code);
  projection.setExtent(tj.tile_matrix.extent);
  status.region = region;
  status.tilesLoaded = 0;
  status.tileErrors = 0;
  const showClasses = document.getElementById('show-classes').checked;
  const showDistance = document.getElementById('show-distance').checked;
  const opacity = Number(document.getElementById('distance-opacity').value);
  const classes = webMercator ? xyzLayer(tj, 'classes', showClasses, 1)
    : tileLayer(region, tj, 'classes', showClasses, 1);
  const distance = webMercator ? xyzLayer(tj, 'road_distance', showDistance, opacity)
    : tileLayer(region, tj, 'road_distance', showDistance, opacity);
  // The whole region in view at first.
  const extent = webMercator ? transformExtent(tj.bounds, 'EPSG:4326', 'EPSG:3857') : tj.tile_matrix.extent;
  const view = webMercator
    ? new View({ minZoom: tj.minzoom, maxZoom: tj.maxzoom + 2 })
    : new View({ projection, resolutions: [8, 4, 2, 1, 0.5, 0.25, 0.125], constrainResolution: true,
                 extent: tj.tile_matrix.extent });
  trackMaxZoom = webMercator ? tj.maxzoom : 4;
  const layers = [classes, distance, new VectorLayer({ source: trackSource, style: trackStyle })];
  if (!map) {
    const dragAndDrop = new DragAndDrop({ formatConstructors: [GeoJSON] });
    const controls = defaultControls().extend([
      new ScaleLine({ units: 'metric' }),
      new MousePosition({ coordinateFormat: formatCursor, className: 'cursor-position', placeholder: '&nbsp;' }),
    ]);
    map = new Map({ target: 'map', layers, view, controls,
                    interactions: defaultInteractions().extend([dragAndDrop]) });
    dragAndDrop.on('addfeatures', (event) => {
      const text = new GeoJSON().writeFeatures(event.features, { featureProjection: map.getView().getProjection() });
      addTrack(text, event.file.name);
    });
    map.on('singleclick', (event) => {
      const hit = map.forEachFeatureAtPixel(event.pixel, (f) => (f.getGeometry().getType() === 'Point' ? f : null));
      const p = hit ? hit.getProperties() : null;
      document.getElementById('info').textContent = p
        ? ['frame', 'entropy', 'etu_weight', 'heading_deg', 'position_error_m', 'heading_error_deg',
           'lateral_error_m', 'longitudinal_error_m', 'relocalized']
          .filter((k) => p[k] !== undefined)
          .map((k) => `${k}: ${typeof p[k] === 'number' ? p[k].toFixed(3) : p[k]}`).join('\n')
        : '';
    });
  } else {
    map.setLayers(layers);
    map.setView(view);
  }
  view.fit(extent);
  document.getElementById('show-classes').onchange = (e) => classes.setVisible(e.target.checked);
  document.getElementById('show-distance').onchange = (e) => distance.setVisible(e.target.checked);
  document.getElementById('distance-opacity').oninput = (e) => distance.setOpacity(Number(e.target.value));
  showStatus();
}

// A PMTiles archive beside the page, without a server: its header gives the zooms and bounds.
async function showArchive(url) {
  const source = new PMTilesRasterSource({ url, attributions: [], crossOrigin: 'anonymous' });
  source.on('tileloadend', () => { status.tilesLoaded++; showStatus(); });
  source.on('tileloaderror', () => { status.tileErrors++; showStatus(); });
  status.region = url;
  const view = new View({ maxZoom: 24 });
  map = new Map({ target: 'map', layers: [new TileLayer({ source }), new VectorLayer({ source: trackSource, style: trackStyle })],
                  view, controls: defaultControls().extend([new ScaleLine({ units: 'metric' })]) });
  regionCode = 'EPSG:3857';
  const header = await new PMTiles(url).getHeader();
  trackMaxZoom = header.maxZoom;
  view.fit(transformExtent([header.minLon, header.minLat, header.maxLon, header.maxLat], 'EPSG:4326', 'EPSG:3857'));
  view.setZoom(Math.max(view.getZoom(), header.minZoom));
  for (const id of ['region', 'show-classes', 'show-distance', 'distance-opacity']) document.getElementById(id).disabled = true;
  showStatus();
}

async function main() {
  const params = new URLSearchParams(window.location.search);
  if (params.get('pmtiles')) {
    try {
      await showArchive(params.get('pmtiles'));
      if (params.get('track')) await loadTrack(params.get('track'));
    } catch (e) {
      status.error = e.message;
      showStatus();
    }
    return;
  }
  try {
    const catalog = await fetchJson('catalog');
    const select = document.getElementById('region');
    for (const r of catalog.regions) select.add(new Option(r.id, r.id));
    const wanted = params.get('region');
    if (wanted) select.value = wanted;
    select.onchange = () => showRegion(select.value);
    await showRegion(select.value);
    if (params.get('distance') === '1') {
      document.getElementById('show-distance').checked = true;
      document.getElementById('show-distance').dispatchEvent(new Event('change'));
    }
    if (params.get('track')) await loadTrack(params.get('track'));
  } catch (e) {
    status.error = e.message;
    showStatus();
  }
  const colourSelect = document.getElementById('colour-by');
  if (params.get('colour') === 'entropy') colourSelect.value = 'entropy';
  colourSelect.onchange = () => setColourBy(colourSelect.value);
  setColourBy(colourSelect.value);
  document.getElementById('track-form').onsubmit = (e) => {
    e.preventDefault();
    loadTrack(document.getElementById('track-url').value);
  };
}

main();
