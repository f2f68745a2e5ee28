// Opens an MCAP file in Foxglove Studio 1.48 (the app the npm package
// @foxglove/studio-base 1.48.0 ships prebuilt), headless in Chromium, with a
// layout in Studio's export format, and says what a user would see:
//
//   node tests/js/studio/open.js --mcap FILE --layout LAYOUT.json --time RFC3339
//        [--screenshots DIR] [--timeout-s 240] [--problems-only]
//        [--expect-problem TEXT]
//
// It serves the app, React 17, the layout and the file from one local HTTP
// server that answers byte ranges (as Studio's remote-file source needs),
// opens the file through the URL (`ds=remote-file`), seeks to --time, and
// reads: the Problems list of the data-source sidebar, every panel's error
// boundary and the errors the app reports, for each Plot panel (each tab of
// a Tab panel in turn) the pixels of each series' colour on its canvas, the
// 3D panel's coloured pixels and where they lie, and the Log panel's rows.
// With --problems-only (a file the layout was not made for, such as an
// input recording) only the Problems list and errors are judged. With
// --expect-problem, a problem containing TEXT is expected (the file has it
// by design): it must be listed, and is no failure. Prints one
// JSON object; exits 0 when nothing is wrong, 1 when something
// is (the object's `failures` say what), 2 when it could not run.
"use strict";

const fs = require("fs");
const http = require("http");
const path = require("path");
const puppeteer = require("puppeteer-core");

const HERE = __dirname;
const MODULES = path.join(HERE, "..", "node_modules");
/// Pixels of a series' colour below which a plot counts as not drawing it
/// (the legend hidden; a single measurement's point covers about 9).
const MIN_SERIES_PIXELS = 5;
/// Share of the 3D canvas that the coloured track must cover.
const MIN_TRACK_SHARE = 0.003;
/// Width of the 3D canvas's edge strips (pixels) where no label's ink may
/// lie: a label there is cut off by the panel. The strips leave out the
/// top fifth, where the app's own buttons and hints sit.
const EDGE_PX = 10;

function parseArgs(argv) {
  const args = { timeoutS: 240 };
  for (let i = 0; i < argv.length; i += 2) {
    if (argv[i] === "--problems-only") {
      args.problemsOnly = true;
      i -= 1;
      continue;
    }
    const [key, value] = [argv[i], argv[i + 1]];
    if (value === undefined) throw new Error(`${key} needs a value`);
    if (key === "--mcap") args.mcap = path.resolve(value);
    else if (key === "--layout") args.layout = path.resolve(value);
    else if (key === "--time") args.time = value;
    else if (key === "--screenshots") args.screenshots = path.resolve(value);
    else if (key === "--timeout-s") args.timeoutS = Number(value);
    else if (key === "--expect-problem") args.expectProblem = value;
    else throw new Error(`unknown argument ${key}`);
  }
  for (const k of ["mcap", "layout", "time"]) {
    if (!args[k]) throw new Error(`--${k} is required`);
  }
  return args;
}

const MIME = {
  ".html": "text/html",
  ".js": "text/javascript",
  ".json": "application/json",
  ".wasm": "application/wasm",
  ".png": "image/png",
  ".ttf": "font/ttf",
  ".mcap": "application/octet-stream",
};

/// The one local server: / (this folder), /studio/ (the app's assets),
/// /vendor/ (React 17's UMD builds), /layout.json and /data/FILE.mcap.
function serve(args) {
  const roots = {
    "/studio/": path.join(MODULES, "@foxglove/studio-base/assets"),
    "/vendor/react/": path.join(MODULES, "react"),
    "/vendor/react-dom/": path.join(MODULES, "react-dom"),
  };
  const route = (pathname) => {
    if (pathname === "/layout.json") return args.layout;
    if (pathname === "/data/" + path.basename(args.mcap)) return args.mcap;
    for (const [prefix, dir] of Object.entries(roots)) {
      if (pathname.startsWith(prefix)) return path.join(dir, pathname.slice(prefix.length));
    }
    return path.join(HERE, pathname === "/" ? "index.html" : pathname);
  };
  const server = http.createServer((req, res) => {
    const pathname = decodeURIComponent(new URL(req.url, "http://local").pathname);
    if (pathname.split("/").includes("..")) {
      res.writeHead(400);
      return res.end();
    }
    const file = route(pathname);
    fs.stat(file, (err, st) => {
      if (err || !st.isFile()) {
        res.writeHead(404);
        return res.end();
      }
      const headers = {
        "Content-Type": MIME[path.extname(file)] ?? "application/octet-stream",
        "Accept-Ranges": "bytes",
        "Cache-Control": "no-store",
      };
      const range = /^bytes=(\d+)-(\d*)$/.exec(req.headers.range ?? "");
      let [start, end] = [0, st.size - 1];
      if (range) {
        start = Number(range[1]);
        end = range[2] ? Math.min(Number(range[2]), end) : end;
        if (start > end) {
          res.writeHead(416, { "Content-Range": `bytes */${st.size}` });
          return res.end();
        }
        headers["Content-Range"] = `bytes ${start}-${end}/${st.size}`;
      }
      headers["Content-Length"] = end - start + 1;
      res.writeHead(range ? 206 : 200, headers);
      const stream = fs.createReadStream(file, { start, end });
      stream.on("error", () => res.destroy());
      res.on("close", () => stream.destroy());
      stream.pipe(res);
    });
  });
  return new Promise((resolve) => server.listen(0, "127.0.0.1", () => resolve(server)));
}

/// Reads a PNG (a screenshot of one of the app's canvases, which are
/// offscreen and cannot be read back) on a canvas of the page. Counts, for
/// each series colour (`#rrggbb`), the pixels that are that colour blended
/// with the background (the most common pixel) at an opacity of 30 % or
/// more (antialiased lines), each pixel counted for the nearest colour;
/// the saturated ("coloured") pixels with their centroid; and the dark
/// pixels (labels' ink) in the edge strips (EDGE_PX wide: left, right and
/// bottom, below the top fifth).
async function pixels(page, png, colours) {
  return page.evaluate(
    async (b64, colours, edgePx) => {
      const img = new Image();
      img.src = "data:image/png;base64," + b64;
      await img.decode();
      const canvas = document.createElement("canvas");
      [canvas.width, canvas.height] = [img.width, img.height];
      const ctx = canvas.getContext("2d");
      ctx.drawImage(img, 0, 0);
      const d = ctx.getImageData(0, 0, img.width, img.height).data;
      const counts = new Map();
      for (let i = 0; i < d.length; i += 4) {
        const key = (d[i] << 16) | (d[i + 1] << 8) | d[i + 2];
        counts.set(key, (counts.get(key) ?? 0) + 1);
      }
      const bgKey = [...counts.entries()].reduce((a, b) => (b[1] > a[1] ? b : a))[0];
      const bg = [(bgKey >> 16) & 255, (bgKey >> 8) & 255, bgKey & 255];
      const rgb = colours.map((c) => [1, 3, 5].map((k) => parseInt(c.slice(k, k + 2), 16)));
      const near = colours.map(() => 0);
      let coloured = 0;
      let edgeInk = 0;
      let [sx, sy] = [0, 0];
      for (let i = 0; i < d.length; i += 4) {
        const p = [d[i], d[i + 1], d[i + 2]];
        let best = -1;
        let bestResidual = 24;
        rgb.forEach((c, k) => {
          const dc = c.map((v, j) => v - bg[j]);
          const dp = p.map((v, j) => v - bg[j]);
          const norm = dc.reduce((s, v) => s + v * v, 0);
          if (norm === 0) return;
          const alpha = Math.min(1, dc.reduce((s, v, j) => s + v * dp[j], 0) / norm);
          if (alpha < 0.3) return;
          const residual = Math.hypot(...dp.map((v, j) => v - alpha * dc[j]));
          if (residual < bestResidual) [best, bestResidual] = [k, residual];
        });
        if (best >= 0) near[best] += 1;
        if (Math.max(...p) - Math.min(...p) > 80) {
          coloured += 1;
          const q = i / 4;
          sx += q % img.width;
          sy += Math.floor(q / img.width);
        }
        const [x, y] = [(i / 4) % img.width, Math.floor(i / 4 / img.width)];
        const inStrip =
          y >= img.height / 5 && (x < edgePx || x >= img.width - edgePx || y >= img.height - edgePx);
        // Grey to black: a label's antialiased strokes, not the track's colours.
        if (inStrip && Math.max(...p) < 200 && Math.max(...p) - Math.min(...p) < 40) edgeInk += 1;
      }
      return {
        width: img.width,
        height: img.height,
        near,
        coloured,
        centroid: coloured ? [sx / coloured / img.width, sy / coloured / img.height] : null,
        edgeInk,
      };
    },
    png.toString("base64"),
    colours,
    EDGE_PX,
  );
}

/// A screenshot of `canvas` with everything else in `panel` hidden (the
/// plot's floating legend shows each series' colour by itself).
async function canvasAlone(panel, canvas) {
  const toggle = (hide) =>
    panel.evaluate(
      (root, canvas, hide) => {
        const keep = new Set();
        for (let e = canvas; e && e !== root.parentElement; e = e.parentElement) keep.add(e);
        for (const e of root.querySelectorAll("*")) {
          if (keep.has(e) || canvas.contains(e)) continue;
          if (hide) {
            e.dataset.tortwinVisibility = e.style.visibility;
            e.style.visibility = "hidden";
          } else {
            e.style.visibility = e.dataset.tortwinVisibility ?? "";
            delete e.dataset.tortwinVisibility;
          }
        }
      },
      canvas,
      hide,
    );
  await toggle(true);
  try {
    return await canvas.screenshot();
  } finally {
    await toggle(false);
  }
}

async function panel(page, id) {
  return page.$(`[data-testid~="${id}"]`);
}

/// Opens the tab titled `title` of a Tab panel.
async function openTab(page, title, settleMs) {
  const handle = await page.evaluateHandle(
    (title) =>
      [...document.querySelectorAll('[data-testid="toolbar-tab"]')].find((t) => t.title === title) ?? null,
    title,
  );
  const tab = handle.asElement();
  if (!tab) return false;
  await tab.click();
  await new Promise((r) => setTimeout(r, settleMs));
  return true;
}

async function problems(page) {
  const clicked = await page.evaluate(() => {
    const tab = [...document.querySelectorAll('[role="tab"]')].find((t) =>
      t.textContent.trim().startsWith("Problems"),
    );
    if (tab) tab.click();
    return Boolean(tab);
  });
  if (!clicked) return { found: false, items: [] };
  await new Promise((r) => setTimeout(r, 500));
  return page.evaluate(() => ({
    found: true,
    empty: document.body.innerText.includes("No problems found"),
    items: [...document.querySelectorAll(".MuiListItemText-primary")].map((e) => e.textContent),
  }));
}

/// One look at everything the layout shows.
async function look(page, layout, shots, settleMs) {
  const seen = { plots: {}, panelErrors: [], log: [], threeD: null };
  const configs = layout.configById;
  seen.panelErrors = await page.evaluate(() =>
    [...document.querySelectorAll("[data-testid^='panel-mouseenter-container']")]
      .filter((p) => p.innerText.includes("This panel encountered an unexpected error"))
      .map((p) => p.getAttribute("data-testid")),
  );
  // Plots: a Tab panel shows one tab at a time.
  const plotIds = Object.keys(configs).filter((id) => id.startsWith("Plot!"));
  const tabsOf = {};
  for (const [id, config] of Object.entries(configs)) {
    if (id.startsWith("Tab!")) {
      for (const tab of config.tabs) tabsOf[tab.layout] = tab.title;
    }
  }
  for (const id of plotIds) {
    if (tabsOf[id]) await openTab(page, tabsOf[id], settleMs);
    const element = await panel(page, id);
    const canvas = element && (await element.$("canvas"));
    if (!canvas) {
      seen.plots[id] = null;
      continue;
    }
    const png = await canvasAlone(element, canvas);
    const series = configs[id].paths.map((p) => p.label ?? p.value);
    const counted = await pixels(page, png, configs[id].paths.map((p) => p.color));
    seen.plots[id] = Object.fromEntries(series.map((s, k) => [s, counted.near[k]]));
    if (shots) {
      fs.writeFileSync(path.join(shots, `studio-${id.replace("!", "-")}.png`), await page.screenshot());
    }
  }
  for (const id of Object.keys(configs).filter((id) => id.startsWith("3D!"))) {
    const element = await panel(page, id);
    const canvas = element && (await element.$("canvas"));
    if (!canvas) continue;
    const png = await canvas.screenshot();
    const counted = await pixels(page, png, []);
    if (shots) fs.writeFileSync(path.join(shots, `studio-${id.replace("!", "-")}.png`), png);
    seen.threeD = {
      id,
      share: counted.coloured / (counted.width * counted.height),
      centroid: counted.centroid,
      edgeInk: counted.edgeInk,
    };
  }
  for (const id of Object.keys(configs).filter((id) => id.startsWith("RosOut!"))) {
    const element = await panel(page, id);
    if (!element) continue;
    seen.log = await element.$$eval("div[title]", (rows) => rows.map((r) => r.innerText.replace(/\s+/g, " ")));
  }
  return seen;
}

function judge(seen, problemList, appErrors, problemsOnly, expectProblem) {
  const failures = [];
  const expected = (p) => expectProblem !== undefined && p.includes(expectProblem);
  const unexpected = problemList.items.filter((p) => !expected(p));
  if (!problemList.found) failures.push("the Problems tab was not found");
  else if (unexpected.length > 0 || (!problemList.empty && problemList.items.length === 0)) {
    failures.push(`Problems: ${JSON.stringify(problemList.items)}`);
  }
  if (expectProblem !== undefined && !problemList.items.some(expected)) {
    failures.push(`the expected problem "${expectProblem}" is not listed`);
  }
  for (const id of seen.panelErrors) failures.push(`panel error: ${id}`);
  for (const e of appErrors) failures.push(`app error: ${e.split("\n")[0]}`);
  if (problemsOnly) return failures;
  for (const [id, series] of Object.entries(seen.plots)) {
    if (series === null) {
      failures.push(`${id}: no chart`);
      continue;
    }
    // A tribometer's reading comes once a day per site: its measured point
    // lies under its twin's when they agree, so the pair is judged as one.
    const sparse = {};
    for (const [label, n] of Object.entries(series)) {
      if (label.includes("(tribometer)")) {
        const pair = label.replace(/, (measured|twin)$/, "");
        sparse[pair] = (sparse[pair] ?? 0) + n;
      } else if (n < MIN_SERIES_PIXELS) {
        failures.push(`${id}: series "${label}" not drawn (${n} pixels)`);
      }
    }
    for (const [pair, n] of Object.entries(sparse)) {
      if (n < MIN_SERIES_PIXELS) failures.push(`${id}: "${pair}" not drawn (${n} pixels)`);
    }
  }
  if (!seen.threeD) failures.push("3D: no canvas");
  else {
    const { share, centroid, edgeInk } = seen.threeD;
    if (share < MIN_TRACK_SHARE) failures.push(`3D: the track is not shown (${(share * 100).toFixed(2)} % coloured)`);
    else if (centroid.some((c) => c < 0.2 || c > 0.8)) {
      failures.push(`3D: the track is off-centre (centroid at ${centroid.map((c) => c.toFixed(2))} of the panel)`);
    }
    if (edgeInk > 0) failures.push(`3D: labels cut off by the panel's edges (${edgeInk} dark pixels at its edges)`);
  }
  if (seen.log.length === 0) failures.push("Log: no rows");
  return failures;
}

async function main() {
  const args = parseArgs(process.argv.slice(2));
  const layout = JSON.parse(fs.readFileSync(args.layout, "utf8"));
  if (args.screenshots) fs.mkdirSync(args.screenshots, { recursive: true });
  const server = await serve(args);
  const base = `http://127.0.0.1:${server.address().port}`;
  const url =
    `${base}/?ds=remote-file&ds.url=${encodeURIComponent(`${base}/data/${path.basename(args.mcap)}`)}` +
    `&layoutId=tortwin&time=${encodeURIComponent(args.time)}`;
  const browser = await puppeteer.launch({
    executablePath: process.env.CHROMIUM ?? "/usr/bin/chromium",
    headless: true,
    args: ["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"],
    defaultViewport: { width: 1600, height: 1000 },
    protocolTimeout: args.timeoutS * 1000,
  });
  const console_ = [];
  try {
    const page = await browser.newPage();
    page.on("console", (m) => console_.push(`${m.type()}: ${m.text()}`));
    page.on("pageerror", (e) => console_.push(`pageerror: ${e.message}`));
    await page.goto(url, { waitUntil: "load", timeout: args.timeoutS * 1000 });
    await page.waitForFunction(() => window.__studioMounted || window.__studioErrors.length > 0, {
      timeout: args.timeoutS * 1000,
    });
    // The file is read in a worker and the plots fill as blocks arrive:
    // look every few seconds until everything shows or time runs out.
    const deadline = Date.now() + args.timeoutS * 1000;
    // The data-source sidebar shows "—" under "Duration" until the file's
    // summary is read (src/components/DataSourceInfoView.js); problems with
    // its channels are known by then.
    await page.waitForFunction(
      () => {
        const label = [...document.querySelectorAll("span, p")].find(
          (e) => e.childElementCount === 0 && /^duration$/i.test(e.textContent.trim()),
        );
        const value = label?.nextElementSibling;
        return Boolean(value && /\d/.test(value.textContent));
      },
      { timeout: args.timeoutS * 1000 },
    );
    let seen, problemList, failures, appErrors, expectedOnly;
    // A Tab panel draws a tab's plot anew when it opens: each pass waits
    // longer for it (a slow machine gets more time, not the same again).
    let settleMs = 1500;
    do {
      await new Promise((r) => setTimeout(r, 4000));
      problemList = await problems(page);
      seen = await look(page, layout, null, settleMs);
      settleMs = Math.min(2 * settleMs, 20000);
      appErrors = await page.evaluate(() => window.__studioErrors);
      failures = judge(seen, problemList, appErrors, args.problemsOnly, args.expectProblem);
      // Problems with the file's channels do not go away: no need to wait
      // for the plots then (an expected one aside).
      expectedOnly = problemList.items.every((p) => args.expectProblem !== undefined && p.includes(args.expectProblem));
    } while (failures.length > 0 && expectedOnly && Date.now() < deadline);
    if (args.screenshots) {
      await look(page, layout, args.screenshots, settleMs);
      // Back to the first tab for the overview.
      const tabs = Object.values(layout.configById).find((c) => c.tabs);
      if (tabs) await openTab(page, tabs.tabs[0].title, settleMs);
      fs.writeFileSync(path.join(args.screenshots, "studio.png"), await page.screenshot());
    }
    const verdict = { url, problems: problemList.items, ...seen, appErrors, failures, console: console_.slice(-20) };
    process.stdout.write(JSON.stringify(verdict, null, 1) + "\n");
    return failures.length === 0 ? 0 : 1;
  } finally {
    await browser.close();
    server.close();
  }
}

main().then(
  (code) => process.exit(code),
  (e) => {
    process.stderr.write(`open.js: ${(e && e.stack) || e}\n`);
    process.exit(2);
  },
);
