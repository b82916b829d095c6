// The web page of `starnav serve`: a client of the server's astrometry.net (nova) API.
// login -> upload (image) or url_upload (source list) -> poll the submission and its job ->
// show starnav's answer (api/jobs/N/starnav). No libraries: the page must work offline.
"use strict";

(() => {
  const $ = (id) => document.getElementById(id);
  const POLL_MS = 500;
  let session = null;

  // ---- input: image or source list, drag and drop ----

  function showMode() {
    const xy = $("mode-xy").checked;
    $("image-input").hidden = xy;
    $("xy-input").hidden = !xy;
  }

  function setUpDrop() {
    const drop = $("drop");
    for (const type of ["dragenter", "dragover"]) {
      drop.addEventListener(type, (ev) => {
        ev.preventDefault();
        drop.classList.add("over");
      });
    }
    drop.addEventListener("dragleave", () => drop.classList.remove("over"));
    drop.addEventListener("drop", (ev) => {
      ev.preventDefault();
      drop.classList.remove("over");
      if (ev.dataTransfer.files.length) $("file").files = ev.dataTransfer.files;
    });
  }

  // The number in input `id` (null when empty); `what` names it in the error.
  function number(id, what) {
    const input = $(id);
    const v = Number(input.value);
    if (input.validity.badInput || !Number.isFinite(v)) throw new Error(`${what}: not a number.`);
    return input.value.trim() === "" ? null : v;
  }

  // The nova hints of the form (astrometry.net's submission fields).
  function hints() {
    const out = { parity: Number($("parity").value) };
    const lo = number("scale-lower", "Field size, from");
    const hi = number("scale-upper", "Field size, to");
    if ((lo === null) !== (hi === null)) throw new Error("Field size: give both ends.");
    if (lo !== null) {
      Object.assign(out, { scale_units: $("scale-units").value, scale_type: "ul",
                           scale_lower: lo, scale_upper: hi });
    }
    const ra = number("center-ra", "RA");
    const dec = number("center-dec", "Dec");
    const radius = number("radius", "Radius");
    if ((ra === null) !== (dec === null)) throw new Error("Position: give both RA and Dec.");
    if (radius !== null && ra === null) throw new Error("Position: a radius needs RA and Dec.");
    if (ra !== null) Object.assign(out, { center_ra: ra, center_dec: dec });
    if (radius !== null) out.radius = radius;
    // nova's field; the server's answers then need this session, which api/login's cookie
    // gives every request of the page (its fetches, the picture, the downloads)
    if ($("private").checked) out.publicly_visible = "n";
    return out;
  }

  // "x y" or "x,y" a line (blank lines and # comments skipped) -> {x: [...], y: [...]}.
  function parseXY(text) {
    const x = [];
    const y = [];
    text.split(/\r?\n/).forEach((line, i) => {
      const s = line.trim();
      if (s === "" || s.startsWith("#")) return;
      const parts = s.split(/\s*[,\s]\s*/);
      const [a, b] = parts.map(Number);
      if (parts.length !== 2 || !Number.isFinite(a) || !Number.isFinite(b)) {
        throw new Error(`Source positions, line ${i + 1}: "${s}" is not "x y" or "x,y".`);
      }
      x.push(a);
      y.push(b);
    });
    if (!x.length) throw new Error("Source positions: paste at least one \"x y\" line.");
    return { x, y };
  }

  // What to send: {image: bool, send(session) -> the server's reply}. Throws on a bad form.
  function request() {
    const args = hints();
    if ($("mode-image").checked) {
      const file = $("file").files[0];
      if (!file) throw new Error("Choose an image file first.");
      return { image: true, send: (key) => post("api/upload", { ...args, session: key }, file) };
    }
    const { x, y } = parseXY($("xy").value);
    const width = number("width", "Image width");
    const height = number("height", "Image height");
    if (!(width > 0 && height > 0)) throw new Error("Source positions need the image's size.");
    const xy = { x, y, image_width: width, image_height: height };
    const send = (key) => post("api/url_upload", { ...args, ...xy, session: key });
    return { image: false, send };
  }

  // ---- the API ----

  async function post(path, args, file) {
    const body = new FormData();
    body.append("request-json", JSON.stringify(args));
    if (file) body.append("file", file, file.name);
    return readJSON(await fetch(path, { method: "POST", body }));
  }

  async function get(path) {
    return readJSON(await fetch(path, { cache: "no-store" }));
  }

  async function readJSON(resp) {
    // nova's API answers JSON as text/plain (so does starnav's); anything else, or text that
    // is not JSON (a proxy's error page), is an HTTP error
    const type = resp.headers.get("content-type") || "";
    const fail = new Error(`${resp.url}: HTTP ${resp.status}`);
    if (!type.includes("json") && !type.includes("text/plain")) throw fail;
    try {
      return JSON.parse(await resp.text());
    } catch {
      throw fail;
    }
  }

  async function login() {
    const askedBefore = !$("key-row").hidden;
    const reply = await post("api/login", { apikey: $("apikey").value });
    if (reply.status === "success") return reply.session;
    $("key-row").hidden = false;
    $("apikey").focus();
    throw new Error(askedBefore ? `The server refused the key: ${reply.errormessage}.`
                                : "This server needs an API key: enter it and solve again.");
  }

  // ---- a job's progress ----

  const sleep = (ms) => new Promise((done) => setTimeout(done, ms));

  function showStatus(state, seconds, extra = "") {
    const status = $("status");
    status.dataset.state = state;
    status.textContent = `${state} — ${seconds.toFixed(0)} s${extra}`;
  }

  // Poll submission `subid` until its job is done; returns the job's id and state.
  async function follow(subid) {
    const t0 = performance.now();
    const elapsed = () => (performance.now() - t0) / 1000;
    let state = "queued";
    let jobId = null;
    const ticker = setInterval(() => showStatus(state, elapsed()), 1000);
    try {
      for (;;) {
        if (jobId === null) {
          const sub = await get(`api/submissions/${subid}`);
          if (sub.error_message) return { jobId, state: "failure", reason: sub.error_message };
          if (sub.jobs && sub.jobs.length && sub.jobs[0] !== null) jobId = sub.jobs[0];
        }
        if (jobId !== null) {
          const nova = (await get(`api/jobs/${jobId}`)).status;
          state = nova === "processing" ? "queued" : nova;
        }
        showStatus(state, elapsed());
        if (state === "success" || state === "failure") return { jobId, state, seconds: elapsed() };
        await sleep(POLL_MS);
      }
    } finally {
      clearInterval(ticker);
    }
  }

  // ---- the answer ----

  const pad = (n) => String(n).padStart(2, "0");
  const sigma = (v) => (v >= 10 ? v.toFixed(0) : v.toPrecision(2));

  function raSexagesimal(deg) {
    let t = Math.round((((deg % 360) + 360) % 360) / 15 * 3600 * 100) % (24 * 3600 * 100);
    const h = Math.floor(t / 360000);
    t -= h * 360000;
    const m = Math.floor(t / 6000);
    return `${pad(h)}h ${pad(m)}m ${((t - m * 6000) / 100).toFixed(2).padStart(5, "0")}s`;
  }

  function decSexagesimal(deg) {
    let t = Math.round(Math.abs(deg) * 3600 * 10);
    const d = Math.floor(t / 36000);
    t -= d * 36000;
    const m = Math.floor(t / 600);
    const s = ((t - m * 600) / 10).toFixed(1).padStart(4, "0");
    return `${deg < 0 ? "-" : "+"}${pad(d)}° ${pad(m)}′ ${s}″`;
  }

  function angle(id, degrees, sexagesimal) {
    const deg = document.createElement("span");
    deg.className = "deg";
    deg.textContent = degrees;
    const sexa = document.createElement("span");
    sexa.className = "sexa";
    sexa.textContent = sexagesimal;
    $(id).replaceChildren(deg, sexa);
  }

  function showSolution(job, image) {
    const r = job.result;
    const sign = r.dec_deg < 0 ? "" : "+";
    angle("ra", `${r.ra_deg.toFixed(6)}°`, raSexagesimal(r.ra_deg));
    angle("dec", `${sign}${r.dec_deg.toFixed(6)}°`, decSexagesimal(r.dec_deg));
    $("sigma-boresight").textContent = `± ${sigma(r.sigma_boresight_arcsec)}″ (1σ, total)`;
    $("roll").textContent = `${r.roll_deg.toFixed(4)}° ± ${sigma(r.sigma_roll_arcsec)}″ (1σ)`;
    let fov = `${r.fov_deg.toFixed(4)}°`;
    if (r.camera_model === "pinhole" && r.sigma_focal_px > 0) {
      // fov = 2 atan(W / 2f): its 1-sigma from the focal length's
      const w = r.width;
      const f = r.focal_px;
      fov += ` ± ${sigma((w * r.sigma_focal_px / (f * f + w * w / 4)) * 180 / Math.PI)}° (1σ)`;
    }
    $("fov").textContent = fov;
    $("focal").textContent = `${r.focal_px.toFixed(1)} px ` + (r.sigma_focal_px > 0
      ? `± ${sigma(r.sigma_focal_px)} px (1σ)` : "(held fixed)") + ` — ${r.camera_model} model`;
    $("scale").textContent = `${r.plate.pixscale_arcsec.toFixed(3)}″ per pixel`;
    $("parity-out").textContent = r.parity > 0
      ? "+1: the sky as seen (astrometry.net \"neg\")"
      : "−1: mirrored (astrometry.net \"pos\")";
    $("matched").textContent = `${r.n_matched} of ${r.stars.length} sources`;
    $("rms").textContent = `${r.rms_px.toFixed(2)} px`;
    $("fmp").textContent = r.false_match_probability.toExponential(1);

    $("dl-wcs").href = `wcs_file/${job.id}`;
    $("dl-fits").href = `new_fits_file/${job.id}`;
    $("dl-fits").hidden = !image;
    $("dl-json").href = `json_file/${job.id}`;

    const rows = r.stars.filter((s) => s.catalog_id !== null).map((s) => {
      const tr = document.createElement("tr");
      const cells = [s.catalog_id, s.name || "", s.mag == null ? "" : s.mag.toFixed(2),
                     (s.x + 0.5).toFixed(2), (s.y + 0.5).toFixed(2), s.residual_px.toFixed(2)];
      for (const text of cells) {
        const td = document.createElement("td");
        td.textContent = text;
        tr.append(td);
      }
      return tr;
    });
    $("stars").tBodies[0].replaceChildren(...rows);
    $("solution").hidden = false;
    $("identified").hidden = false;
  }

  function showPicture(job, solved) {
    const img = $("annotated");
    img.onload = () => { $("picture").hidden = false; };
    img.onerror = () => { $("picture").hidden = true; };
    $("picture-caption").textContent = solved
      ? "The detected sources (circles) and the identified catalog stars (squares)."
      : "The detected sources: not solved.";
    img.src = `annotated_display/${job.id}?finished=${job.finished}`;  // a new job, a new URL
  }

  function reset(subid) {
    for (const id of ["solution", "picture", "identified", "reason"]) $(id).hidden = true;
    $("annotated").removeAttribute("src");
    $("job-id").textContent = subid;
    $("progress").hidden = false;
    showStatus("queued", 0);
  }

  async function solve(ev) {
    ev.preventDefault();
    $("form-error").textContent = "";
    let what;
    try {
      what = request();
    } catch (err) {
      $("form-error").textContent = err.message;
      return;
    }
    $("submit").disabled = true;
    try {
      session = session || await login();
      let reply = await what.send(session);
      if (reply.status === "error" && /^no session/.test(reply.errormessage)) {
        session = await login();  // the server forgot it (a new data dir)
        reply = await what.send(session);
      }
      if (reply.status !== "success") throw new Error(`The server refused: ${reply.errormessage}`);
      reset(reply.subid);
      const done = await follow(reply.subid);
      const job = done.jobId === null ? null : await get(`api/jobs/${done.jobId}/starnav`);
      const took = job && job.started && job.finished
        ? ` (the server worked ${(job.finished - job.started).toFixed(1)} s)` : "";
      showStatus(done.state, done.seconds || 0, took);
      if (done.state === "success") {
        showSolution(job, what.image);
      } else {
        $("reason").textContent = done.reason || (job && job.reason) || "no reason given";
        $("reason").hidden = false;
      }
      if (job) showPicture(job, done.state === "success");
    } catch (err) {
      $("form-error").textContent = err.message;
    } finally {
      $("submit").disabled = false;
    }
  }

  $("mode-image").addEventListener("change", showMode);
  $("mode-xy").addEventListener("change", showMode);
  $("solve-form").addEventListener("submit", solve);
  setUpDrop();
  showMode();
})();
