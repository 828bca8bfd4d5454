// Serves the Foxglove Studio web bundle (from the pinned @foxglove/studio-base package) and one
// MCAP file on 127.0.0.1, opens the file in headless Chromium with the layout beside this
// script, seeks to the given time and writes a PNG. Run by screenshot.sh; a documentation
// tool, not a test. Every failure exits non-zero with the reason.
//
// node shoot.mjs --mcap FILE --at SECONDS --out PNG --chromium PATH [--width 1280 --height 800]
//
// --at is the moment to show, in seconds after the recording's first message.

import { closeSync, createReadStream, existsSync, openSync, readSync, statSync, writeFileSync } from "node:fs";
import { createServer } from "node:http";
import { dirname, extname, join, normalize, sep } from "node:path";
import { fileURLToPath } from "node:url";
import puppeteer from "puppeteer-core";

const here = dirname(fileURLToPath(import.meta.url));

function fail(msg) {
  console.error(`shoot: ${msg}`);
  process.exit(1);
}

function parseArgs(argv) {
  const args = { width: 1280, height: 800, timeoutS: 120 };
  for (let i = 0; i < argv.length; i += 2) {
    const [key, value] = [argv[i], argv[i + 1]];
    if (value === undefined) fail(`${key} needs a value`);
    switch (key) {
      case "--mcap": args.mcap = value; break;
      case "--at": args.at = Number(value); break;
      case "--out": args.out = value; break;
      case "--chromium": args.chromium = value; break;
      case "--width": args.width = Number(value); break;
      case "--height": args.height = Number(value); break;
      case "--timeout": args.timeoutS = Number(value); break;
      default: fail(`unknown argument ${key}`);
    }
  }
  for (const k of ["mcap", "at", "out", "chromium"]) {
    if (!args[k]) fail(`--${k} is required`);
  }
  if (!existsSync(args.mcap)) fail(`no MCAP file at ${args.mcap}`);
  if (!existsSync(args.chromium)) fail(`no Chromium at ${args.chromium}`);
  if (!Number.isFinite(args.at) || args.at < 0) fail(`--at must be a number of seconds >= 0`);
  return args;
}

// The first and last message log times (ns) from the Statistics record of an MCAP file's
// summary section (the recorder always writes one).
function messageTimeRange(path) {
  const fd = openSync(path, "r");
  try {
    const size = statSync(path).size;
    const read = (pos, len) => {
      const buf = Buffer.alloc(len);
      if (readSync(fd, buf, 0, len, pos) !== len) fail(`${path}: short read at ${pos}`);
      return buf;
    };
    const magic = Buffer.from([0x89, 0x4d, 0x43, 0x41, 0x50, 0x30, 0x0d, 0x0a]);
    if (size < 8 + 29 + 8 || !read(size - 8, 8).equals(magic)) {
      fail(`${path} is not a finished MCAP file (no closing magic; \`microrobot recover\` finishes one)`);
    }
    const footer = read(size - 8 - 29, 29);
    if (footer[0] !== 0x02) fail(`${path}: no footer record`);
    const summaryStart = Number(footer.readBigUInt64LE(9));
    if (summaryStart === 0) fail(`${path}: no summary section`);
    const summary = read(summaryStart, size - 8 - 29 - summaryStart);
    for (let pos = 0; pos + 9 <= summary.length; ) {
      const op = summary[pos];
      const len = Number(summary.readBigUInt64LE(pos + 1));
      if (op === 0x0b) {
        // Statistics: message_count u64, schema u16, channel u32, attachment u32,
        // metadata u32, chunk u32, message_start_time u64, message_end_time u64, ...
        const body = pos + 9;
        const start = summary.readBigUInt64LE(body + 8 + 2 + 4 * 4);
        const end = summary.readBigUInt64LE(body + 8 + 2 + 4 * 4 + 8);
        return { start, end };
      }
      pos += 9 + len;
    }
    fail(`${path}: no Statistics record in the summary`);
  } finally {
    closeSync(fd);
  }
}

function rfc3339(ns) {
  const ms = Number(ns / 1000000n);
  const frac = String(ns % 1000000000n).padStart(9, "0");
  return new Date(ms).toISOString().replace(/\.\d{3}Z$/, `.${frac}Z`);
}

const TYPES = {
  ".html": "text/html; charset=utf-8",
  ".js": "text/javascript; charset=utf-8",
  ".json": "application/json",
  ".wasm": "application/wasm",
  ".png": "image/png",
  ".svg": "image/svg+xml",
  ".woff2": "font/woff2",
  ".woff": "font/woff",
  ".ttf": "font/ttf",
  ".mcap": "application/octet-stream",
};

// Only these packages are served under /vendor/.
const VENDORED = ["react", "react-dom", "@foxglove/studio-base"];

function resolvePath(urlPath, mcap) {
  if (urlPath === "/" || urlPath === "/index.html") return join(here, "web", "index.html");
  if (urlPath === "/main.js") return join(here, "web", "main.js");
  if (urlPath === "/layout.json") return join(here, "layout.json");
  if (urlPath === "/recording.mcap") return mcap;
  if (urlPath.startsWith("/vendor/")) {
    const rest = normalize(decodeURIComponent(urlPath.slice("/vendor/".length)));
    const pkg = VENDORED.find((p) => rest === p || rest.startsWith(p + sep));
    if (!pkg || rest.includes("..")) return undefined;
    return join(here, "node_modules", rest);
  }
  return undefined;
}

function serve(mcap) {
  const missing = [];
  const server = createServer((req, res) => {
    const url = new URL(req.url, "http://127.0.0.1");
    if (url.pathname === "/favicon.ico") {
      res.writeHead(204).end();
      return;
    }
    const file = resolvePath(url.pathname, mcap);
    if (!file || !existsSync(file) || !statSync(file).isFile()) {
      missing.push(url.pathname);
      res.writeHead(404).end();
      return;
    }
    const size = statSync(file).size;
    const headers = {
      "Content-Type": TYPES[extname(file)] ?? "application/octet-stream",
      "Accept-Ranges": "bytes",
      "Cache-Control": "no-store",
    };
    const range = /^bytes=(\d*)-(\d*)$/.exec(req.headers.range ?? "");
    let start = 0;
    let end = size - 1;
    let status = 200;
    if (range) {
      if (range[1] === "") {
        start = Math.max(0, size - Number(range[2]));
      } else {
        start = Number(range[1]);
        if (range[2] !== "") end = Math.min(end, Number(range[2]));
      }
      if (start > end || start >= size) {
        res.writeHead(416, { "Content-Range": `bytes */${size}` }).end();
        return;
      }
      status = 206;
      headers["Content-Range"] = `bytes ${start}-${end}/${size}`;
    }
    headers["Content-Length"] = String(end - start + 1);
    res.writeHead(status, headers);
    if (req.method === "HEAD") {
      res.end();
      return;
    }
    createReadStream(file, { start, end }).pipe(res);
  });
  return new Promise((resolve, reject) => {
    server.on("error", reject);
    server.listen(0, "127.0.0.1", () => resolve({ server, port: server.address().port, missing }));
  });
}

// Counts the pixels of the arm's colours (joint spheres orange, links blue as drawn by the
// recording's scene) inside the given rectangle of a PNG, decoded by the page itself.
async function armPixels(page, png, rect) {
  return page.evaluate(
    async (b64, r) => {
      const img = new Image();
      img.src = `data:image/png;base64,${b64}`;
      await img.decode();
      const c = document.createElement("canvas");
      c.width = img.width;
      c.height = img.height;
      const ctx = c.getContext("2d");
      ctx.drawImage(img, 0, 0);
      const d = ctx.getImageData(r.x, r.y, r.width, r.height).data;
      let orange = 0;
      let blue = 0;
      for (let i = 0; i < d.length; i += 4) {
        const [R, G, B] = [d[i], d[i + 1], d[i + 2]];
        if (R > 150 && G > 60 && G < 170 && B < 90 && R - B > 100) orange++;
        if (B > 120 && B - R > 60 && G > 70 && G < 170) blue++;
      }
      return { orange, blue };
    },
    png.toString("base64"),
    rect,
  );
}

async function main() {
  const args = parseArgs(process.argv.slice(2));
  const range = messageTimeRange(args.mcap);
  const at = range.start + BigInt(Math.round(args.at * 1e9));
  if (at > range.end) {
    fail(`--at ${args.at} s is past the recording's end (${Number(range.end - range.start) / 1e9} s)`);
  }
  const { server, port, missing } = await serve(args.mcap);
  const origin = `http://127.0.0.1:${port}`;
  const params = new URLSearchParams({
    ds: "remote-file",
    "ds.url": `${origin}/recording.mcap`,
    layoutId: "microrobot",
    time: rfc3339(at),
  });
  const url = `${origin}/?${params}`;
  console.error(`shoot: serving on ${origin}, opening ${url}`);

  const browser = await puppeteer.launch({
    executablePath: args.chromium,
    headless: true,
    args: [
      "--no-sandbox",
      "--use-angle=swiftshader",
      "--enable-unsafe-swiftshader",
      "--ignore-gpu-blocklist",
      `--window-size=${args.width},${args.height}`,
    ],
  });
  const problems = [];
  try {
    const page = await browser.newPage();
    await page.setViewport({ width: args.width, height: args.height });
    page.on("pageerror", (err) => problems.push(`page error: ${err.message}`));
    page.on("console", (msg) => {
      if (msg.type() === "error") problems.push(`console error: ${msg.text()}`);
    });
    await page.goto(url, { waitUntil: "load", timeout: args.timeoutS * 1000 });

    const deadline = Date.now() + args.timeoutS * 1000;
    const remaining = () => Math.max(1000, deadline - Date.now());
    await page
      .waitForFunction(() => window.__screenshotMounted === true || window.__screenshotError, {
        timeout: remaining(),
      })
      .catch(() => fail("the viewer page never mounted"));
    const pageError = await page.evaluate(() => window.__screenshotError);
    if (pageError) fail(`the viewer page failed: ${pageError}`);

    // The 3D panel's canvas and the plot's canvas, both laid out with a size.
    await page
      .waitForFunction(
        () => [...document.querySelectorAll("canvas")].filter((c) => c.clientWidth > 100).length >= 2,
        { timeout: remaining() },
      )
      .catch(() => fail("the layout's panels never drew a canvas (3D panel and plot expected)"));

    // Seeking to the deep link's time happens once the player is ready; the 3D panel then
    // draws the frame at that time. Poll screenshots until the arm is on screen and steady.
    const canvas3d = await page.evaluate(() => {
      const c = [...document.querySelectorAll("canvas")]
        .filter((x) => x.clientWidth > 100)
        .sort((a, b) => a.getBoundingClientRect().left - b.getBoundingClientRect().left)[0];
      const r = c.getBoundingClientRect();
      return { x: Math.round(r.left), y: Math.round(r.top), width: Math.round(r.width), height: Math.round(r.height) };
    });
    let png;
    let pixels = { orange: 0, blue: 0 };
    let previous;
    for (;;) {
      await new Promise((r) => setTimeout(r, 3000));
      // The viewer reports a file it cannot read as player problems (its Problems list).
      const fatal = problems.filter((p) => p.startsWith("page error") || p.includes("Player problem"));
      if (fatal.length > 0) {
        writeFileSync(args.out + ".failed.png", Buffer.from(await page.screenshot({ type: "png" })));
        fail(`the viewer reported problems (screen in ${args.out}.failed.png): ${JSON.stringify(problems.slice(0, 10))}`);
      }
      png = Buffer.from(await page.screenshot({ type: "png" }));
      pixels = await armPixels(page, png, canvas3d);
      const steady = previous && Math.abs(previous.orange - pixels.orange) <= 2 && Math.abs(previous.blue - pixels.blue) <= 2;
      console.error(`shoot: arm pixels in the 3D panel: ${JSON.stringify(pixels)}`);
      if (pixels.orange > 30 && pixels.blue > 30 && steady) break;
      previous = pixels;
      if (Date.now() > deadline) {
        writeFileSync(args.out + ".failed.png", png);
        fail(
          `the 3D panel shows no arm after ${args.timeoutS} s (orange ${pixels.orange}, blue ${pixels.blue} px); ` +
            `last screen in ${args.out}.failed.png; browser problems: ${JSON.stringify(problems.slice(0, 10))}; ` +
            `404s: ${JSON.stringify(missing.slice(0, 10))}`,
        );
      }
    }
    writeFileSync(args.out, png);
    console.error(`shoot: wrote ${args.out} (${png.length} bytes)`);
    if (problems.length > 0) {
      console.error(`shoot: the browser reported (not fatal, the arm is drawn): ${JSON.stringify(problems.slice(0, 10))}`);
    }
  } finally {
    await browser.close();
    server.close();
  }
}

main().catch((err) => fail(err && err.stack ? err.stack : String(err)));
