// lazperf_bench.js — decode throughput of laz-perf's WASM decoder (npm package laz-perf) under
// Node, on the same files as laz_bench, for bench_laz.sh. Never a build or test dependency:
// bench_laz.sh installs the package into a temporary directory when npm can reach it.
//
//   node lazperf_bench.js RUNS FILE...      (NODE_PATH must hold laz-perf)
//
// For each file: every point decoded with LASZip.getPoint, RUNS times; prints
// "FILE POINTS MEDIAN_SECONDS MEDIAN_CPU_SECONDS FNV1A64" (CPU: process.cpuUsage, user +
// system, of this single-threaded decode; the hash over all point records, in file order, the
// same hash laz_bench prints for splatd's decoder).
'use strict';
const fs = require('fs');
const { createLazPerf } = require('laz-perf');

function fnv(h, bytes) {
  // 64-bit FNV-1a in two 32-bit halves (BigInt per byte would dominate the timing)
  let lo = h[0], hi = h[1];
  for (let i = 0; i < bytes.length; i++) {
    lo = (lo ^ bytes[i]) >>> 0;
    // multiply by the FNV prime 0x100000001b3 = 2^40 + 0x1b3
    const l = lo * 0x1b3, carry = Math.floor(l / 4294967296);
    const nhi = (hi * 0x1b3 + carry + ((lo << 8) >>> 0)) >>> 0;
    lo = l >>> 0;
    hi = nhi;
  }
  h[0] = lo; h[1] = hi;
}

(async () => {
  const runs = parseInt(process.argv[2], 10);
  const LazPerf = await createLazPerf();
  for (const file of process.argv.slice(3)) {
    const bytes = fs.readFileSync(file);
    const times = [], cpus = [];
    let count = 0, hash = '';
    for (let r = 0; r < runs; r++) {
      const filePtr = LazPerf._malloc(bytes.length);
      LazPerf.HEAPU8.set(bytes, filePtr);
      const t0 = process.hrtime.bigint(), c0 = process.cpuUsage();
      const laszip = new LazPerf.LASZip();
      laszip.open(filePtr, bytes.length);
      count = laszip.getCount();
      const len = laszip.getPointLength();
      const dataPtr = LazPerf._malloc(len);
      const h = [0x84222325, 0xcbf29ce4];
      for (let i = 0; i < count; i++) {
        laszip.getPoint(dataPtr);
        if (r === 0) fnv(h, LazPerf.HEAPU8.subarray(dataPtr, dataPtr + len));
      }
      const t1 = process.hrtime.bigint(), c1 = process.cpuUsage(c0);
      if (r === 0) hash = (h[1] >>> 0).toString(16).padStart(8, '0') + (h[0] >>> 0).toString(16).padStart(8, '0');
      else {
        times.push(Number(t1 - t0) / 1e9);
        cpus.push((c1.user + c1.system) / 1e6);
      }
      laszip.delete();
      LazPerf._free(dataPtr);
      LazPerf._free(filePtr);
    }
    times.sort((a, b) => a - b);
    cpus.sort((a, b) => a - b);
    const mid = Math.floor(times.length / 2);
    console.log(`${file} ${count} ${times[mid].toFixed(6)} ${cpus[mid].toFixed(6)} ${hash}`);
  }
})();
