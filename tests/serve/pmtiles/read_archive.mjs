// Reads every tile the server answers back from a PMTiles archive with the npm registry's PMTiles
// decoder, and checks that the archive holds no tile the server does not answer.
//   node read_archive.mjs ARCHIVE BASE_URL REGION LAYER STYLE [ZOOMS]
// BASE_URL is a running `seqloc serve` of the region. Prints "N passed, M failed".
import fs from "node:fs";
import { PMTiles } from "pmtiles";

// A PMTiles source over a local file (the package's own sources read URLs and browser Files).
class FileSource {
  constructor(path) {
    this.path = path;
    this.fd = fs.openSync(path, "r");
  }
  getKey() {
    return this.path;
  }
  async getBytes(offset, length) {
    const buffer = Buffer.alloc(length);
    const n = fs.readSync(this.fd, buffer, 0, length, offset);
    return { data: buffer.buffer.slice(buffer.byteOffset, buffer.byteOffset + n) };
  }
}

const [archive, base, region, layer, style] = process.argv.slice(2);
const pmtiles = new PMTiles(new FileSource(archive));
const header = await pmtiles.getHeader();
const tilejson = await (await fetch(`${base}/regions/${region}/tilejson.json`)).json();
let passed = 0;
const failures = [];
const check = (ok, what) => (ok ? passed++ : failures.push(what));
// The archive's zooms: those asked for (ZOOMS, "MIN-MAX"), or else the server's.
const [minZoom, maxZoom] = (process.argv[7] ?? `${tilejson.minzoom}-${tilejson.maxzoom}`).split("-").map(Number);
check(header.minZoom === minZoom && header.maxZoom === maxZoom, `zooms ${header.minZoom}-${header.maxZoom}`);
check(header.tileType === 2, `tile type ${header.tileType} (PNG is 2)`);
const metadata = await pmtiles.getMetadata();
check(metadata.attribution === tilejson.attribution, `attribution ${metadata.attribution}`);

const [west, south, east, north] = tilejson.bounds;
let tiles = 0;
for (let z = header.minZoom; z <= header.maxZoom; z++) {
  const n = 2 ** z;
  const column = (lon) => Math.floor(((lon + 180) / 360) * n);
  const row = (lat) => Math.floor(((1 - Math.asinh(Math.tan((lat * Math.PI) / 180)) / Math.PI) / 2) * n);
  // One tile of margin each way: tiles the server does not answer must be absent.
  for (let y = Math.max(0, row(north) - 1); y <= Math.min(n - 1, row(south) + 1); y++) {
    for (let x = Math.max(0, column(west) - 1); x <= Math.min(n - 1, column(east) + 1); x++) {
      const response = await fetch(`${base}/regions/${region}/xyz/${layer}/${z}/${x}/${y}.png?style=${style}`);
      const tile = await pmtiles.getZxy(z, x, y);
      if (response.status === 404) {
        check(tile === undefined, `${z}/${x}/${y}: in the archive, not served`);
        continue;
      }
      const served = Buffer.from(await response.arrayBuffer());
      tiles++;
      check(tile !== undefined && Buffer.from(tile.data).equals(served), `${z}/${x}/${y}: not the server's bytes`);
    }
  }
}
check(tiles > 0, "no tile served");
for (const f of failures.slice(0, 10)) console.error(f);
console.log(`${tiles} tiles read back from ${archive}`);
console.log(`${passed} passed, ${failures.length} failed`);
process.exit(failures.length === 0 ? 0 : 1);
