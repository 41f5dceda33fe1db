// Run the Khronos glTF validator on one .glb/.gltf file and print its JSON report on stdout.
// Usage: node tests/tools/validate_gltf.mjs FILE   (exit 0 when the report was produced, 2 on usage/IO errors)
import { readFileSync } from "node:fs";
import { createRequire } from "node:module";
import path from "node:path";
import { fileURLToPath } from "node:url";

const here = path.dirname(fileURLToPath(import.meta.url));
// The package lives in the repository root's node_modules (installed by `make env`).
const require = createRequire(path.join(here, "..", "..", "package.json"));
const validator = require("gltf-validator");

const file = process.argv[2];
if (!file) {
  console.error("usage: node validate_gltf.mjs FILE.glb");
  process.exit(2);
}
const bytes = new Uint8Array(readFileSync(file));
try {
  const report = await validator.validateBytes(bytes, {
    uri: path.basename(file),
    maxIssues: 0,
    writeTimestamp: false,
  });
  console.log(JSON.stringify(report, null, 2));
} catch (error) {
  console.error(`validator could not read ${file}: ${error}`);
  process.exit(2);
}
