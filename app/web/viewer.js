// The page of `rig view`: controls out as JSON over a WebSocket, JPEG frames in.
// Plain JavaScript, no build step: the relighting runs in Python (render.live_session), the
// page only sends what the person set and shows what comes back.
"use strict";

const $ = (id) => document.getElementById(id);
const TAGS = { 1: "frame", 2: "panorama", 3: "truth", 4: "error" };
const state = { controls: {}, info: null, sentAt: 0, meta: null, paint: null };
let socket = null;

function send(changes) {
  Object.assign(state.controls, changes);
  if (socket && socket.readyState === WebSocket.OPEN) {
    state.sentAt = performance.now();
    socket.send(JSON.stringify({ controls: changes }));
    waitForFrame();
  }
}

// Never "live" while a frame is awaited: a first frame in a new mode opens its engine (the
// paper's sampling, a model's precomputation) and can take seconds; the status counts them.
function waitForFrame() {
  if (state.waiting) return;
  state.waiting = setInterval(() => {
    const seconds = (performance.now() - state.sentAt) / 1000;
    if (seconds > 0.5) setStatus(`rendering… (${seconds.toFixed(0)} s)`);
  }, 250);
}

function frameArrived() {
  clearInterval(state.waiting);
  state.waiting = null;
  setStatus("live");
}

function wrapDegrees(value) {
  return ((((value + 180) % 360) + 360) % 360) - 180;
}

function showControls(c) {
  document.querySelector(`input[name=mode][value=${c.mode}]`).checked = true;
  $("panorama-name").value = c.panorama;
  $("yaw").value = Math.round(wrapDegrees(c.yaw_deg));
  $("yaw-value").textContent = `${Math.round(wrapDegrees(c.yaw_deg))}°`;
  $("exposure").value = Math.log2(c.exposure).toFixed(1);
  $("exposure-value").textContent = `×${c.exposure.toPrecision(3)}`;
  $("k").value = String(c.k);
  $("sampler").value = c.sampler;
  $("modulation").value = c.modulation || "";
  $("truth-on").checked = c.truth;
}

function fillSelect(select, names, keepFirst) {
  const first = keepFirst ? [select.options[0]] : [];
  select.replaceChildren(...first);
  for (const name of names) {
    const option = document.createElement("option");
    option.value = option.textContent = name;
    select.append(option);
  }
}

// The header keeps one line (the pages' controls below must not move under the pointer when a
// message grows); what does not fit is cut and the whole text is the tooltip.
function setStatus(text) {
  $("status").textContent = text;
  $("status").title = text;
}

function showField(info) {
  const text = info.kind === "pixels"
    ? `${info.field} (${info.image_shape[1]} × ${info.image_shape[0]} pixels, ${info.shape[1]} lights)`
    : `${info.field} (${info.kind}, ${info.shape.join(" × ")})`;
  $("field").textContent = text;
  $("field").title = text;
}

function applyState(info) {
  state.info = info;
  showField(info);
  $("best-reason").textContent = info.modes.best;
  $("paper-mode").textContent = info.modes.paper;
  fillSelect($("panorama-name"), info.panoramas, false);
  fillSelect($("modulation"), info.modulations, true);
  fillSelect($("sampler"), info.samplers, false);
  $("truth-on").disabled = !info.has_truth;
  $("orbit-hint").hidden = !info.can_orbit;
  if (info.kind === "pixels") {
    // A capture's own few pixels: shown enlarged (whole steps, each pixel visible) so the
    // frame and its caption are readable.
    const [, width] = info.image_shape;
    $("frame").classList.add("pixels");
    $("frame").style.width = `${Math.max(1, Math.floor(480 / width)) * width}px`;
    if (!state.lightStarted) {
      state.lightStarted = true;
      lightView.start();
    }
  }
  state.controls = { ...info.controls, ...state.controls };
  showControls(state.controls);
}

function showPicture(tag, bytes) {
  const img = $(TAGS[tag]);
  const url = URL.createObjectURL(new Blob([bytes], { type: "image/jpeg" }));
  const old = img.src;
  // The frame's own description (its JSON came just before it): a later one may arrive
  // before this picture is decoded.
  const meta = state.meta;
  img.src = url;
  // decode(): the picture is ready to be painted, not only fetched, when the frame counts as
  // shown; a picture replaced before then rejects, and the next one counts.
  img.decode().then(() => {
    if (old.startsWith("blob:")) URL.revokeObjectURL(old);
    if (TAGS[tag] === "frame" && meta) {
      const total = performance.now() - state.sentAt;
      const parts = Object.entries(meta.ms).map(([k, v]) => `${k} ${v} ms`).join(", ");
      $("frame-time").textContent = `— ${parts}; on screen ${total.toFixed(0)} ms`;
      $("mode-name").textContent = `(${meta.mode}, ${meta.points} samples)`;
      document.body.dataset.frame = String(meta.seq);
    }
    if (TAGS[tag] === "panorama") sizePaint();
  }, () => {});
  if (tag === 3) $("truth-figure").hidden = false;
  if (tag === 4) $("error-figure").hidden = false;
}

function onMessage(event) {
  if (typeof event.data !== "string") {
    const bytes = new Uint8Array(event.data);
    showPicture(bytes[0], bytes.subarray(1));
    return;
  }
  const message = JSON.parse(event.data);
  if (message.type === "frame") {
    state.meta = message;
    state.controls = { ...message.controls };  // a copy: send() edits it, the frame keeps its own
    showControls(message.controls);
    $("notes").replaceChildren(...message.notes.map((n) => Object.assign(
      document.createElement("p"), { textContent: n })));
    frameArrived();
    if (!message.controls.truth) {
      $("truth-figure").hidden = $("error-figure").hidden = true;
    }
    showIdle(message.idle || {});
    // The best mode of a capture is chosen under each panorama: its reason comes with the frame.
    if (message.best) $("best-reason").textContent = message.best;
  } else if (message.type === "warnings") {
    // Folded to one line (the panorama stays in view); the codes say what they are about.
    $("warnings").replaceChildren(...message.warnings.map((w) => Object.assign(
      document.createElement("li"), { textContent: w })));
    const codes = message.warnings.map((w) => (w.match(/^warning \(([^)]+)\)/) || [, "warning"])[1]);
    $("warnings-box").hidden = message.warnings.length === 0;
    $("warnings-summary").textContent = `${message.warnings.length} warning${message.warnings.length > 1 ? "s" : ""}: ${codes.join(", ")}`;
  } else if (message.type === "truth") {
    $("truth-error").textContent = `relative RMSE ${(100 * message.relative_rmse).toFixed(2)} %`;
  } else if (message.type === "error") {
    clearInterval(state.waiting);
    state.waiting = null;
    setStatus(`error: ${message.message}`);
  }
}

// Controls that change nothing in this mode: disabled, with the reason beside them.
function showIdle(idle) {
  $("k").disabled = "k" in idle;
  $("sampler").disabled = "sampler" in idle;
  $("modulation-controls").disabled = "modulation" in idle;
  for (const id of ["k", "sampler"]) $(id).title = idle[id] || "";
  $("modulation-controls").title = idle.modulation || "";
  const reasons = [...new Set(Object.values(idle))];
  $("idle-note").hidden = reasons.length === 0;
  $("idle-note").textContent = reasons.join("; ");
}

function connect() {
  const scheme = location.protocol === "https:" ? "wss" : "ws";
  socket = new WebSocket(`${scheme}://${location.host}/api/live`);
  socket.binaryType = "arraybuffer";
  socket.onopen = () => send({});
  socket.onmessage = onMessage;
  socket.onclose = () => { setStatus("disconnected: is rig view still running?"); };
}

async function upload(kind, file) {
  setStatus(`loading ${file.name}…`);
  const response = await fetch(`api/${kind}?name=${encodeURIComponent(file.name)}`, {
    method: "POST", body: file,
  });
  const body = await response.json();
  if (!response.ok) {
    setStatus(`error: ${body.error}`);
    return;
  }
  applyState(body);
  send(kind === "panorama" ? { panorama: body.name } : { modulation: body.name });
}

// Dragging: the panorama rotates (yaw), the view orbits.
function onDrag(element, start, move) {
  element.addEventListener("pointerdown", (down) => {
    if (element === $("panorama") && $("paint-on").checked) return;
    const origin = start();
    element.setPointerCapture(down.pointerId);
    const moved = (event) => move(origin, event.clientX - down.clientX, event.clientY - down.clientY);
    const up = () => {
      element.removeEventListener("pointermove", moved);
      element.removeEventListener("pointerup", up);
    };
    element.addEventListener("pointermove", moved);
    element.addEventListener("pointerup", up);
  });
}

// Painting a modulation map over the panorama: 1 everywhere, brushed to 0 or 4.
function sizePaint() {
  const canvas = $("paint");
  const img = $("panorama");
  if (canvas.width === img.naturalWidth && canvas.height === img.naturalHeight) return;
  canvas.width = img.naturalWidth;
  canvas.height = img.naturalHeight;
  state.paint = new Float32Array(canvas.width * canvas.height).fill(1);
}

function paintAt(event) {
  const canvas = $("paint");
  const box = canvas.getBoundingClientRect();
  const x = Math.round(event.clientX - box.left);
  const y = Math.round(event.clientY - box.top);
  const value = Number($("brush").value);
  const radius = Math.max(4, Math.round(canvas.height / 16));
  const context = canvas.getContext("2d");
  context.fillStyle = value === 0 ? "#f00" : value > 1 ? "#0f0" : "#000";
  context.globalCompositeOperation = value === 1 ? "destination-out" : "source-over";
  context.beginPath();
  context.arc(x, y, radius, 0, 2 * Math.PI);
  context.fill();
  for (let row = Math.max(0, y - radius); row <= Math.min(canvas.height - 1, y + radius); row++) {
    for (let col = x - radius; col <= x + radius; col++) {
      if ((row - y) ** 2 + (col - x) ** 2 > radius * radius) continue;
      const wrapped = ((col % canvas.width) + canvas.width) % canvas.width;
      state.paint[row * canvas.width + wrapped] = value;
    }
  }
}

function paintedMap() {
  // 8-bit grey read as linear weights by the server: x0 -> 0, x1 -> 64, x4 -> 255.
  const canvas = document.createElement("canvas");
  canvas.width = $("paint").width;
  canvas.height = $("paint").height;
  const context = canvas.getContext("2d");
  const image = context.createImageData(canvas.width, canvas.height);
  state.paint.forEach((value, i) => {
    const grey = Math.min(255, Math.round((value / 4) * 255));
    image.data.set([grey, grey, grey, 255], 4 * i);
  });
  context.putImageData(image, 0, 0);
  return new Promise((resolve) => canvas.toBlob(resolve, "image/png"));
}

let painted = 0;

function wire() {
  for (const radio of document.querySelectorAll("input[name=mode]")) {
    radio.addEventListener("change", () => send({ mode: radio.value }));
  }
  $("panorama-name").addEventListener("change", (e) => send({ panorama: e.target.value }));
  $("panorama-file").addEventListener("change", (e) => upload("panorama", e.target.files[0]));
  $("modulation-file").addEventListener("change", (e) => upload("modulation", e.target.files[0]));
  $("yaw").addEventListener("input", (e) => {
    $("yaw-value").textContent = `${e.target.value}°`;
    send({ yaw_deg: Number(e.target.value) });
  });
  $("exposure").addEventListener("input", (e) => {
    const exposure = 2 ** Number(e.target.value);
    $("exposure-value").textContent = `×${exposure.toPrecision(3)}`;
    send({ exposure });
  });
  $("k").addEventListener("change", (e) => send({ k: Number(e.target.value) }));
  $("sampler").addEventListener("change", (e) => send({ sampler: e.target.value }));
  $("modulation").addEventListener("change", (e) => send({ modulation: e.target.value || null }));
  $("truth-on").addEventListener("change", (e) => send({ truth: e.target.checked }));
  onDrag($("panorama"), () => state.controls.yaw_deg, (yaw, dx) => {
    const width = $("panorama").getBoundingClientRect().width;
    // Content follows the pointer: a positive yaw moves the panorama's content left.
    send({ yaw_deg: wrapDegrees(yaw - (dx / width) * 360) });
  });
  onDrag($("frame"), () => [state.controls.azimuth_deg, state.controls.inclination_deg],
    ([azimuth, inclination], dx, dy) => {
      if (!state.info || !state.info.can_orbit) return;
      send({
        azimuth_deg: ((azimuth - dx * 0.5) % 360 + 360) % 360,
        inclination_deg: Math.min(90, Math.max(1, inclination + dy * 0.5)),
      });
    });
  $("frame").addEventListener("wheel", (event) => {
    if (!state.info || !state.info.can_orbit) return;
    event.preventDefault();
    const [low, high] = state.info.zoom_range;
    send({ zoom: Math.min(high, Math.max(low, state.controls.zoom * Math.exp(-event.deltaY * 0.001))) });
  }, { passive: false });
  $("paint-on").addEventListener("change", (e) => { $("paint").hidden = !e.target.checked; });
  $("paint").addEventListener("pointerdown", (down) => {
    paintAt(down);
    const move = (event) => paintAt(event);
    $("paint").addEventListener("pointermove", move);
    $("paint").addEventListener("pointerup", () => $("paint").removeEventListener("pointermove", move), { once: true });
  });
  $("paint-apply").addEventListener("click", async () => {
    painted += 1;
    const blob = await paintedMap();
    upload("modulation", new File([blob], `painted-${painted}.png`));
  });
  $("open-session").addEventListener("click", async () => {
    $("open-session").hidden = true;
    await fetch("api/open", { method: "POST" });
  });
  document.addEventListener("dragover", (e) => e.preventDefault());
  document.addEventListener("drop", (e) => {
    e.preventDefault();
    if (e.dataTransfer.files.length) upload("panorama", e.dataTransfer.files[0]);
  });
}

// The server opens the session after printing the URL (the best mode's fit takes a while):
// say what it is doing until it is ready; a capture's directional light comes first.
async function start() {
  wire();
  for (;;) {
    const info = await (await fetch("api/state")).json();
    if (info.status === "ready") {
      applyState(info);
      document.body.classList.remove("preparing");
      break;
    }
    showField(info);
    if (info.kind === "pixels" && !state.lightStarted) {
      state.lightStarted = true;
      lightView.start();
    }
    if (info.status === "failed") {
      setStatus(`the viewer could not start: ${info.error}`);
      return;
    }
    setStatus(`server: ${info.status}… (${info.elapsed_s} s)`);
    $("open-session").hidden = !info.on_request;
    await new Promise((r) => setTimeout(r, 400));
  }
  setStatus("connecting…");
  connect();
}

start();
