// Run the Khronos glTF validator (npm package gltf-validator) on each file given; print one JSON object:
// {file: {errors, warnings, infos, hints, messages: [[code, severity, pointer, message], ...]}}.
// NODE_PATH must reach the package (tests/test_gltf.py sets it).
const fs = require("fs");
const path = require("path");
const validator = require("gltf-validator");

async function validate(file) {
    const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(file)), {
        uri: path.basename(file),
        maxIssues: 100,
        externalResourceFunction: (uri) => new Promise((resolve, reject) => {
            fs.readFile(path.resolve(path.dirname(file), decodeURIComponent(uri)),
                        (err, data) => (err ? reject(err.toString()) : resolve(new Uint8Array(data))));
        }),
    });
    const i = report.issues;
    return {errors: i.numErrors, warnings: i.numWarnings, infos: i.numInfos, hints: i.numHints,
            messages: i.messages.map((m) => [m.code, m.severity, m.pointer, m.message])};
}

(async () => {
    const out = {};
    for (const file of process.argv.slice(2)) out[file] = await validate(file);
    console.log(JSON.stringify(out));
})().catch((e) => { console.error(String(e)); process.exit(1); });
