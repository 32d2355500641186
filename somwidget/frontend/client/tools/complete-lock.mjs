// Completes package-lock.json with the platform packages a registry could not describe, so that `npm ci` passes.
//
// Why: the npm registry mirror on our build machines serves only some of rollup's per-platform binaries
// (@rollup/rollup-<os>-<cpu>[-<libc>]); `npm install` then leaves the others out of the lock, and `npm ci` refuses
// a lock that misses any optional dependency. This adds an entry for each missing @rollup/rollup-* package: its
// version (rollup pins them exactly), os, cpu and libc read off its name, optional, no integrity. npm skips the
// entries whose platform is not this one, so nothing is fetched here; elsewhere npm fetches the one that matches.
// Run after `npm install` changes the lock:  node tools/complete-lock.mjs
import { readFileSync, writeFileSync } from 'node:fs';

const lockPath = new URL('../package-lock.json', import.meta.url);
const lock = JSON.parse(readFileSync(lockPath, 'utf8'));
const pkgs = lock.packages;
const CPUS = { arm: 'arm', arm64: 'arm64', x64: 'x64', ia32: 'ia32', loong64: 'loong64', ppc64: 'ppc64',
  riscv64: 'riscv64', s390x: 's390x' };
let added = 0;
for (const [path, entry] of Object.entries(pkgs)) {
  const optional = entry.optionalDependencies || {};
  for (const [name, version] of Object.entries(optional)) {
    if (!name.startsWith('@rollup/rollup-') || pkgs[`node_modules/${name}`] || pkgs[`${path}/node_modules/${name}`]) {
      continue;
    }
    const parts = name.slice('@rollup/rollup-'.length).split('-'); // e.g. linux-arm-musleabihf, win32-x64-msvc
    const [os, cpu, abi] = parts;
    if (!CPUS[cpu] || !/^\d+\.\d+\.\d+$/.test(version)) throw new Error(`cannot describe ${name}@${version}`);
    const e = { version, cpu: [CPUS[cpu]], dev: entry.dev || undefined, license: 'MIT', optional: true, os: [os] };
    if (os === 'linux' && abi) e.libc = [abi.startsWith('musl') ? 'musl' : 'glibc'];
    pkgs[`node_modules/${name}`] = e;
    added += 1;
  }
}
const sorted = Object.fromEntries(Object.entries(pkgs).sort(([a], [b]) => (a === '' ? -1 : b === '' ? 1 : a < b ? -1 : 1)));
lock.packages = sorted;
writeFileSync(lockPath, `${JSON.stringify(lock, null, 2)}\n`);
console.log(`complete-lock: added ${added} platform entries`);
