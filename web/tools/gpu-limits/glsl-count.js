// web/tools/gpu-limits/glsl-count.js: what a WebGL implementation counts against its limits,
// from a program's GLSL, where WebGL has no query (session 23's audit, shared since session 24
// with the browser test's emulation of a GPU at WebGL2's 15 varyings, web/test/browser-test.js):
//  - packedRows(vars): rows of 4 components a set of uniforms or varyings takes under the packing
//    rule of GLSL ES 1.00 Appendix A.7; vars = [{t: {name, rows, comps}, size}] (t.name the
//    WebGL type name without the prefix, e.g. FLOAT_VEC3);
//  - varyings(fragmentSource): the fragment shader's inputs that it uses, after preprocess().
// No DOM, no WebGL: tests/browser/unit.mjs runs it in node.

// Packing of uniforms and varyings into rows of 4 components: the algorithm of the GLSL ES 1.00
// specification, Appendix A.7 ("Counting of Varyings and Uniforms"), which WebGL implementations
// apply (ES 3.00 keeps it), written here from that description:
//  1. order: 4-component rows first (mat4, mat2 as 2 rows of 4 components, vec4), then mat3 and
//     vec3 (3 components), then vec2, then scalars; within a kind, larger arrays first;
//  2. the 4-component variables take whole rows from the top down, one after another;
//  3. the 3-component ones take columns 0-2 of the following rows, from the top down;
//  4. vec2s go to columns 0-1 of the remaining rows from the top, and when a variable no longer
//     fits there, to columns 2-3 from the bottom up; a variable is never split between the two;
//  5. each scalar (array) goes to the column whose free run of rows that holds it is the
//     shortest (the first such run and column on a tie), as a contiguous run of rows.
// The set fits in N rows if every step succeeds.
const rank = (t) => ({ FLOAT_MAT4: 0, FLOAT_MAT2: 1, FLOAT_VEC4: 2, INT_VEC4: 2, BOOL_VEC4: 2, UNSIGNED_INT_VEC4: 2, FLOAT_MAT3: 3,
  FLOAT_VEC3: 4, INT_VEC3: 4, BOOL_VEC3: 4, UNSIGNED_INT_VEC3: 4, FLOAT_VEC2: 5, INT_VEC2: 5, BOOL_VEC2: 5, UNSIGNED_INT_VEC2: 5 }[t.name] ?? 6);
const width = (t) => (t.name === 'FLOAT_MAT2' ? 4 : t.comps);  // columns a row of the type takes
export function fits(vars, maxRows) {
  const rowsOf = (v) => v.t.rows * v.size;
  if (vars.some((v) => rowsOf(v) > maxRows)) return false;
  const order = [...vars].sort((a, b) => rank(a.t) - rank(b.t) || b.size - a.size);
  const used = Array.from({ length: maxRows }, () => [false, false, false, false]);  // used[row][column]
  let next = 0;  // the first row after the 4- and 3-component blocks
  const by = (w) => order.filter((v) => width(v.t) === w);
  for (const v of by(4)) { next += rowsOf(v); if (next > maxRows) return false; }
  const first3 = next;
  for (const v of by(3)) { next += rowsOf(v); if (next > maxRows) return false; }
  for (let r = 0; r < next; ++r) for (let c = 0; c < (r < first3 ? 4 : 3); ++c) used[r][c] = true;
  let down = next, up = maxRows;  // columns 0-1 fill [next, down), columns 2-3 fill [up, maxRows)
  for (const v of by(2)) {
    const n = rowsOf(v);
    if (down + n <= maxRows) { for (let r = down; r < down + n; ++r) used[r][0] = used[r][1] = true; down += n; }
    else if (up - n >= next) { for (let r = up - n; r < up; ++r) used[r][2] = used[r][3] = true; up -= n; }
    else return false;
  }
  for (const v of by(1)) {
    const n = rowsOf(v);
    let best = null;
    for (let c = 0; c < 4; ++c) {
      for (let r = 0; r < maxRows;) {
        if (used[r][c]) { ++r; continue; }
        let e = r;
        while (e < maxRows && !used[e][c]) ++e;
        if (e - r >= n && (!best || e - r < best.len)) best = { c, r, len: e - r };
        r = e;
      }
    }
    if (!best) return false;
    for (let r = best.r; r < best.r + n; ++r) used[r][best.c] = true;
  }
  return true;
}
export const packedRows = (vars) => { if (!vars.length) return 0; for (let n = 1; n <= 4096; ++n) if (fits(vars, n)) return n; return Infinity; };

// ---- a small GLSL preprocessor (conditionals, object-like #define / #undef) ----
export function preprocess(src) {
  const macros = new Map();
  const lines = src.split('\n');
  const out = [];
  const stack = [];  // {active, taken, parentActive}
  const active = () => stack.every((s) => s.active);
  const evalIf = (expr) => {
    let e = expr.replace(/\/\/.*$/, '').replace(/defined\s*\(\s*(\w+)\s*\)/g, (_, n) => (macros.has(n) ? '1' : '0')).replace(/defined\s+(\w+)/g, (_, n) => (macros.has(n) ? '1' : '0'));
    for (let k = 0; k < 10; ++k) e = e.replace(/[A-Za-z_]\w*/g, (n) => (macros.has(n) ? `(${macros.get(n) || '0'})` : '0'));
    if (!/^[\d\s()+\-*/%<>=!&|.u]*$/.test(e)) throw new Error(`#if ${expr} -> ${e}`);
    return !!Function(`return (${e.replace(/(\d)u\b/g, '$1')});`)();
  };
  for (const line of lines) {
    const m = line.match(/^\s*#\s*(\w+)\s*(.*)$/);
    if (m) {
      const [, d, rest] = m;
      if (d === 'if' || d === 'ifdef' || d === 'ifndef') {
        const pa = active();
        const c = pa && (d === 'if' ? evalIf(rest) : d === 'ifdef' ? macros.has(rest.trim().split(/\s/)[0]) : !macros.has(rest.trim().split(/\s/)[0]));
        stack.push({ active: c, taken: c, pa });
      } else if (d === 'elif') {
        const s = stack[stack.length - 1];
        stack.pop();
        const pa = active();
        stack.push(s);
        if (s.taken || !pa) s.active = false; else { s.active = evalIf(rest); s.taken = s.active; }
      } else if (d === 'else') {
        const s = stack[stack.length - 1];
        stack.pop(); const pa = active(); stack.push(s);
        s.active = pa && !s.taken; s.taken = true;
      } else if (d === 'endif') stack.pop();
      else if (active()) {
        if (d === 'define') { const mm = rest.match(/^(\w+)(\([^)]*\))?\s*(.*)$/); if (mm) macros.set(mm[1], mm[2] ? '1' : mm[3].replace(/\/\/.*$/, '').trim()); }
        else if (d === 'undef') macros.delete(rest.trim());
      }
      continue;
    }
    if (active()) out.push(line);
  }
  return { text: out.join('\n'), macros };
}
export function varyings(fsSrc) {
  const { text, macros } = preprocess(fsSrc);
  const decl = /^\s*(?:flat\s+|smooth\s+|centroid\s+)*(?:(?:highp|mediump|lowp)\s+)?(?:varying|in)\s+(\w+)\s+(\w+)\s*(?:\[\s*([^\]]+?)\s*\])?\s*;/gm;
  const list = [];
  const typeOf = { float: ['FLOAT', 1], vec2: ['FLOAT_VEC2', 2], vec3: ['FLOAT_VEC3', 3], vec4: ['FLOAT_VEC4', 4], mat3: ['FLOAT_MAT3', 3], mat4: ['FLOAT_MAT4', 4], int: ['INT', 1] };
  for (const m of text.matchAll(decl)) {
    const [, type, name, arr] = m;
    let size = 1;
    if (arr) { let e = arr; for (let k = 0; k < 5; ++k) e = e.replace(/[A-Za-z_]\w*/g, (n) => macros.get(n) ?? n); if (!/^[\d\s()+\-*/%]*$/.test(e)) throw new Error(`array size ${arr} -> ${e}`); size = Number(Function(`return (${e});`)()); }
    const uses = (text.match(new RegExp(`\\b${name}\\b`, 'g')) ?? []).length - 1;
    const [tn, c] = typeOf[type] ?? ['?', 4];
    const t = { name: tn, rows: type === 'mat3' ? 3 : type === 'mat4' ? 4 : 1, comps: c, sampler: false };
    list.push({ name, type, size, used: uses > 0, t });
  }
  const used = list.filter((v) => v.used);
  return {
    naiveVectors: used.reduce((a, v) => a + v.t.rows * v.size, 0),
    packedVectors: packedRows(used),
    components: used.reduce((a, v) => a + v.t.comps * v.t.rows * v.size, 0),
    list: used.map((v) => `${v.type} ${v.name}${v.size > 1 ? `[${v.size}]` : ''}`),
    unused: list.filter((v) => !v.used).map((v) => v.name),
    fragCoord: /\bgl_FragCoord\b/.test(text), frontFacing: /\bgl_FrontFacing\b/.test(text),
    fragmentChars: text.length,
  };
}
