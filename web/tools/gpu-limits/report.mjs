#!/usr/bin/env node
// The report of run-audit.mjs's results.json:
//   node web/tools/gpu-limits/report.mjs RESULTS.json [--table]
// Default: the per-case detail (the same text as session 23's report.py printed); --table: the
// per-configuration markdown table (the columns of docs/web.md "Real GPUs"). run-audit.mjs writes
// both into its work dir (report.txt, table.md). A value above the WebGL2 minimum is marked "!"
// in the detail and bold in the table.
import fs from 'node:fs';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

// WebGL2 (OpenGL ES 3.0) minimums: see run-audit.mjs's header.
export const MIN = { fragmentSamplers: 16, combinedSamplers: 32, fragmentVectors: 224, vertexVectors: 256, varyings: 15, varyingComponents: 60 };

// Python's repr of the values this report prints (so that the text compares with report.py's).
const py = (v) => {
  if (v === true) return 'True';
  if (v === false) return 'False';
  if (typeof v === 'string') return `'${v}'`;
  if (Array.isArray(v)) return `[${v.map(py).join(', ')}]`;
  if (v && typeof v === 'object') return `{${Object.entries(v).map(([k, x]) => `${py(k)}: ${py(x)}`).join(', ')}}`;
  return String(v);
};
const flag = (val, lim) => `${val}${val > lim ? '!' : ''}`;

export function detail(results) {
  const out = [];
  for (const x of results) {
    if (x.env) { out.push(x.env.renderer, `${py(x.env.limits)} floatLinear ${py(x.env.floatLinear)}`); continue; }
    if (x.error) { out.push(`${x.name} ERROR ${x.error.slice(0, 300)}`); continue; }
    const f = x.fabric, v = f.vertex, fr = f.fragment, va = f.varyings, L = x.lights;
    out.push(x.name,
      `   lights dir ${L.directional} spot ${L.spot} point ${L.point} shadow-casting ${L.castShadow}; areaLights ${x.areaLights}; view bands ${x.viewBands}; linked ${py(f.linked)}; shaderErrors ${x.shaderErrors.length}`,
      `   FS samplers ${flag(fr.samplers, 16)} (min 16)  VS samplers ${v.samplers}  combined ${fr.samplers + v.samplers} (min 32)`,
      `   FS uniform vectors naive ${flag(fr.naiveVectors, 224)} packed ${fr.packedVectors} (min 224) | VS naive ${flag(v.naiveVectors, 256)} packed ${v.packedVectors} (min 256)`,
      `   varyings naive ${flag(va.naiveVectors, 15)} packed ${flag(va.packedVectors, 15)} comps ${va.components} (min 15 vec / 60 comps) fragCoord ${py(va.fragCoord)} frontFacing ${py(va.frontFacing)}`,
      `   FS samplers: ${fr.samplerList.join(' ')}`,
      `   FS biggest: ${py(fr.biggest.slice(0, 6))}  VS biggest: ${py(v.biggest.slice(0, 5))}`,
      `   varyings: ${va.list.join(', ')}`);
  }
  return `${out.join('\n')}\n`;
}

// env lights: the directional lights split off the environment (its sun and panels:
// scene.userData.clothfitAreaLights); the drape card's own 3 lights are not counted.
export function table(results) {
  const bold = (s, over) => (over ? `**${s}**` : s);
  const rows = ['| case | env lights | fragment samplers | fragment uniforms (naive / packed) | varyings (packed / components) |',
    '|---|---:|---:|---:|---|'];
  for (const x of results) {
    if (x.env) continue;
    const name = x.name.replaceAll('|', '\\|');
    if (x.error) { rows.push(`| ${name} | error: ${x.error.split('\n')[0].slice(0, 120)} | | | |`); continue; }
    const fr = x.fabric.fragment, va = x.fabric.varyings;
    rows.push(`| ${name}${x.fabric.linked ? '' : ' (link failed)'} | ${x.areaLights} | ${bold(fr.samplers, fr.samplers > MIN.fragmentSamplers)} | `
      + `${bold(`${fr.naiveVectors} / ${fr.packedVectors}`, fr.packedVectors > MIN.fragmentVectors)} | `
      + `${bold(`${va.packedVectors} / ${va.components}`, va.packedVectors > MIN.varyings || va.components > MIN.varyingComponents)} |`);
  }
  const env = results.find((x) => x.env)?.env;
  const head = env ? `${env.renderer}: MAX_TEXTURE_IMAGE_UNITS ${env.limits.MAX_TEXTURE_IMAGE_UNITS}, MAX_FRAGMENT_UNIFORM_VECTORS ${env.limits.MAX_FRAGMENT_UNIFORM_VECTORS}, `
    + `MAX_VARYING_VECTORS ${env.limits.MAX_VARYING_VECTORS}, OES_texture_float_linear ${env.floatLinear}\n`
    + `bold: above the WebGL2 minimum (${MIN.fragmentSamplers} samplers, ${MIN.fragmentVectors} fragment uniform vectors, ${MIN.varyings} varyings / ${MIN.varyingComponents} components)\n\n` : '';
  return `${head}${rows.join('\n')}\n`;
}

if (process.argv[1] && fileURLToPath(import.meta.url) === path.resolve(process.argv[1])) {
  const file = process.argv.slice(2).find((a) => !a.startsWith('--'));
  if (!file) { console.error('usage: node web/tools/gpu-limits/report.mjs RESULTS.json [--table]'); process.exit(2); }
  const results = JSON.parse(fs.readFileSync(file, 'utf8'));
  process.stdout.write(process.argv.includes('--table') ? table(results) : detail(results));
}
