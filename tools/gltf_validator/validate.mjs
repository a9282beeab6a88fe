// Validate one .gltf or .glb file with the Khronos glTF-Validator and print its JSON report.
//
//   node tools/gltf_validator/validate.mjs FILE [--max-issues N]
//
// External resources (buffers, images named by relative URI) are read next to FILE. Exit code:
// 0 when the report has no errors, 1 when it has errors, 2 when the file could not be read or
// the validator could not parse it at all (the message goes to stderr).
import { readFile } from "node:fs/promises";
import path from "node:path";
import validator from "gltf-validator";

const args = process.argv.slice(2);
if (args.length < 1) {
  console.error("usage: validate.mjs FILE [--max-issues N]");
  process.exit(2);
}
const file = path.resolve(args[0]);
let maxIssues = 1000;
const at = args.indexOf("--max-issues");
if (at >= 0) maxIssues = Number(args[at + 1]);

let data;
try {
  data = await readFile(file);
} catch (err) {
  console.error(`${file}: ${err.message}`);
  process.exit(2);
}

try {
  const report = await validator.validateBytes(new Uint8Array(data), {
    uri: path.basename(file),
    maxIssues,
    externalResourceFunction: (uri) =>
      readFile(path.resolve(path.dirname(file), decodeURIComponent(uri))).then((b) => new Uint8Array(b)),
  });
  report.validatorVersion = validator.version();
  // exitCode, not exit(): exit() would cut off a large report still being written to a pipe
  process.stdout.write(JSON.stringify(report, null, 1) + "\n");
  process.exitCode = report.issues.numErrors > 0 ? 1 : 0;
} catch (err) {
  console.error(`${file}: validator failed: ${err}`);
  process.exit(2);
}
