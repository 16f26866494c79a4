// Validate glTF files with the Khronos glTF validator; print one JSON report per file
// (an array, in argument order). Usage: node validate.mjs FILE.glb [FILE.gltf ...]
import { readFile } from "node:fs/promises";
import validator from "gltf-validator";

const reports = [];
for (const path of process.argv.slice(2)) {
  const bytes = new Uint8Array(await readFile(path));
  reports.push(await validator.validateBytes(bytes, { uri: path, maxIssues: 0 }));
}
process.stdout.write(JSON.stringify(reports));
