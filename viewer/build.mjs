// Bundles src/main.js (three.js, @msgpack/msgpack) into the Python package's static files.
// Run by scripts/setup.sh (npm ci && npm run build); the output is git-ignored package data.
import { build } from "esbuild";
import { fileURLToPath } from "node:url";
import path from "node:path";

const here = path.dirname(fileURLToPath(import.meta.url));
await build({
  entryPoints: [path.join(here, "src", "main.js")],
  outfile: path.join(here, "..", "server", "diathermy", "service", "static", "viewer", "viewer.js"),
  bundle: true,
  format: "iife",
  target: "es2020",
  minify: true,
  legalComments: "eof",
  logLevel: "info",
});
