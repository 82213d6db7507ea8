// Bundles the viewer (src/, three.js) into service/static/viewer.js, the file the service
// serves; the bundle is committed so the page works offline and CI needs no npm. The first
// line records the SHA-256 of the sources and the lock file, which a test compares with
// the files in the repository, so a stale bundle is caught without running npm.
import { createHash } from "node:crypto";
import { readFileSync, readdirSync, writeFileSync } from "node:fs";
import { dirname, join } from "node:path";
import { fileURLToPath } from "node:url";
import { build } from "esbuild";

const here = dirname(fileURLToPath(import.meta.url));
const out = join(here, "..", "service", "static", "viewer.js");

export function sourceDigest() {
  const hash = createHash("sha256");
  const files = ["package-lock.json", ...readdirSync(join(here, "src")).sort()
    .filter((name) => name.endsWith(".js")).map((name) => join("src", name))];
  for (const file of files) {
    hash.update(file + "\n");
    hash.update(readFileSync(join(here, file)));
  }
  return hash.digest("hex");
}

const result = await build({
  entryPoints: [join(here, "src", "main.js")],
  bundle: true,
  minify: true,
  format: "iife",
  target: "es2020",
  legalComments: "eof",
  write: false,
});
const banner = `/* curvature viewer bundle; sources sha256 ${sourceDigest()} (web/build.mjs) */\n`;
writeFileSync(out, banner + result.outputFiles[0].text);
console.log(`wrote ${out} (${(result.outputFiles[0].contents.length / 1024).toFixed(0)} KiB)`);
