// Checks Grafana dashboard JSON files (default: telegraf/dashboards/grafana-*.json) against
// Grafana's dashboard schema as @grafana/schema publishes it: the TypeScript types generated
// from Grafana's CUE kinds (npm has no JSON Schema of a dashboard). Each file becomes
// `export const dashboard = <its JSON> satisfies Schema<Dashboard>;` and the TypeScript compiler
// checks it: a wrong type, a missing required property or an unknown key (excess property
// check) is an error. `__inputs` (the export wrapper Grafana's import reads, not part of the
// dashboard model) is left out. Schema<T> accepts an enum member's string value where the
// types name the enum (JSON carries "value", the types MappingType.ValueToText).
// Usage: node tools/grafana-schema/check.mjs [FILE...]; exit 0 when every file checks.
import { execFileSync } from 'node:child_process';
import { mkdtempSync, readFileSync, readdirSync, rmSync, writeFileSync } from 'node:fs';
import { basename, dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const repo = resolve(here, '..', '..');
let files = process.argv.slice(2);
if (files.length === 0) {
  const dir = join(repo, 'telegraf', 'dashboards');
  files = readdirSync(dir)
    .filter((f) => f.startsWith('grafana-') && f.endsWith('.json'))
    .map((f) => join(dir, f));
}
const work = mkdtempSync(join(here, '.check-'));
let failed = false;
try {
  const sources = [];
  for (const [i, file] of files.entries()) {
    let dashboard;
    try {
      dashboard = JSON.parse(readFileSync(file, 'utf8'));
    } catch (e) {
      console.error(`${file}: not JSON: ${e.message}`);
      failed = true;
      continue;
    }
    delete dashboard.__inputs;
    const ts = join(work, `d${i}_${basename(file).replace(/[^A-Za-z0-9]/g, '_')}.ts`);
    writeFileSync(
      ts,
      `// ${file}\nimport type { Dashboard } from '@grafana/schema';\n` +
        'type Schema<T> = T extends string ? (string extends T ? T : `${T}`) : T extends (infer U)[] ? Schema<U>[] : T extends object ? { [K in keyof T]: Schema<T[K]> } : T;\n' +
        `export const dashboard = ${JSON.stringify(dashboard, null, 1)} satisfies Schema<Dashboard>;\n`,
    );
    sources.push([ts, file]);
  }
  if (sources.length > 0) {
    try {
      execFileSync(
        join(here, 'node_modules', '.bin', 'tsc'),
        ['--noEmit', '--strict', '--skipLibCheck', '--module', 'commonjs', '--moduleResolution', 'node',
          '--target', 'es2020', ...sources.map(([ts]) => ts)],
        { cwd: here, encoding: 'utf8', stdio: ['ignore', 'pipe', 'pipe'] },
      );
    } catch (e) {
      let out = `${e.stdout ?? ''}${e.stderr ?? ''}`;
      for (const [ts, file] of sources) {
        out = out.split(ts.slice(here.length + 1)).join(file);
      }
      console.error(out.trim() || e.message);
      failed = true;
    }
  }
} finally {
  rmSync(work, { recursive: true, force: true });
}
if (!failed) {
  console.log(`grafana-schema: ${files.length} dashboard(s) check against @grafana/schema`);
}
process.exit(failed ? 1 : 0);
