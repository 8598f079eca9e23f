// The directional light of `rig view` for a field of pixels (an RTI capture): WebGL2.
//
// The server writes the field's PTM and HSH fits in the RTI web format (app/light_view.py,
// render/web_export.py: info.json, coefficient planes, deep-zoom tiles for large images); this
// page relights them on the GPU: per pixel, colour = sum_j base_j(light) (byte_j / 255 - bias_j)
// scale_j, the sum the RTI viewers compute, with the project's bases (exact pi, no elevation
// floor). A frame costs one draw per visible tile, with no round trip to the server.
//
// Controls: drag the hemisphere pad or the image to move the light (x right, y up, as the
// camera sees it); shift-drag (or the middle button) pans, the wheel zooms about the pointer,
// a double click fits the image. Modes: the fit (HSH or PTM), its normals, specular
// enhancement (the fit's colour plus a Blinn-Phong highlight on the normals).
"use strict";

const lightView = (() => {
  const $ = (id) => document.getElementById(id);
  const MAX_TERMS = 9;
  // Tiles per level kept in memory (each a texture array of the model's planes).
  const TILE_CACHE = 256;

  const VERTEX = `#version 300 es
    in vec2 corner;                // 0..1 over the quad
    uniform vec4 rect;             // the quad in image pixels: x0, y0, x1, y1
    uniform vec4 uvRect;           // the texture area it shows: u0, v0, u1, v1
    uniform vec3 view;             // image pixel -> canvas pixel: scale, offset x, offset y
    uniform vec2 canvas;           // canvas size (pixels)
    uniform vec2 image;            // image size (pixels)
    out vec2 uv;
    out vec2 imageUv;
    void main() {
      vec2 p = mix(rect.xy, rect.zw, corner);
      vec2 c = p * view.x + view.yz;
      gl_Position = vec4(c.x / canvas.x * 2.0 - 1.0, 1.0 - c.y / canvas.y * 2.0, 0.0, 1.0);
      uv = mix(uvRect.xy, uvRect.zw, corner);
      imageUv = p / image;
    }`;

  const FRAGMENT = `#version 300 es
    precision highp float;
    precision highp sampler2DArray;
    uniform sampler2DArray planes;
    uniform sampler2D normals;
    uniform int terms;
    uniform float weights[${MAX_TERMS}];
    uniform vec3 scale[${MAX_TERMS}];
    uniform vec3 bias[${MAX_TERMS}];
    uniform int mode;              // 0 the fit, 1 normals, 2 specular enhancement
    uniform vec3 light;
    uniform vec3 specular;         // diffuse gain, specular gain, exponent
    in vec2 uv;
    in vec2 imageUv;
    out vec4 colour;
    vec3 relit() {
      vec3 sum = vec3(0.0);
      for (int j = 0; j < ${MAX_TERMS}; j++) {
        if (j >= terms) break;
        vec3 value = (texture(planes, vec3(uv, float(j))).rgb - bias[j]) * scale[j];
        sum += weights[j] * value;
      }
      return sum;
    }
    void main() {
      if (mode == 1) {
        colour = vec4(texture(normals, imageUv).rgb, 1.0);
        return;
      }
      vec3 c = relit();
      if (mode == 2) {
        vec3 n = normalize(texture(normals, imageUv).rgb * 2.0 - 1.0);
        vec3 h = normalize(light + vec3(0.0, 0.0, 1.0));
        float highlight = pow(max(dot(n, h), 0.0), specular.z);
        c = specular.x * c + specular.y * highlight;
      }
      colour = vec4(clamp(c, 0.0, 1.0), 1.0);
    }`;

  const state = {
    gl: null, program: null, uniforms: {}, info: null, models: {}, model: null,
    light: [0, 0, 1], view: { scale: 1, x: 0, y: 0 }, mode: 0,
    specular: [0.6, 0.5, 40], normals: null, tiles: new Map(), frames: 0, drawn: 0,
    pending: false, ready: false, fitsReady: false, firstModel: null, serverStatus: "",
  };

  // --- the bases: the project's (processing.sample_models), in the viewer's order --------
  function weights(type, light) {
    const [x, y, z] = light;
    if (type === "image") return [1];
    if (type === "ptm") return [1, x, y, x * x, x * y, y * y];
    let phi = Math.atan2(y, x);
    if (phi < 0) phi += 2 * Math.PI;
    const theta = Math.acos(Math.min(1, Math.max(-1, z)));
    const ct = Math.cos(theta);
    const ct2 = ct * ct;
    const root = Math.sqrt(Math.max(0, ct - ct2));
    const pi = Math.PI;
    return [
      1 / Math.sqrt(2 * pi),
      Math.sqrt(6 / pi) * (Math.cos(phi) * root),
      Math.sqrt(3 / (2 * pi)) * (-1 + 2 * ct),
      Math.sqrt(6 / pi) * (root * Math.sin(phi)),
      Math.sqrt(30 / pi) * (Math.cos(2 * phi) * (-ct + ct2)),
      Math.sqrt(30 / pi) * (Math.cos(phi) * (-1 + 2 * ct) * root),
      Math.sqrt(5 / (2 * pi)) * (1 - 6 * ct + 6 * ct2),
      Math.sqrt(30 / pi) * ((-1 + 2 * ct) * root * Math.sin(phi)),
      Math.sqrt(30 / pi) * ((-ct + ct2) * Math.sin(2 * phi)),
    ];
  }

  // --- loading ------------------------------------------------------------------------------
  function loadImage(url) {
    return new Promise((resolve, reject) => {
      const img = new Image();
      img.onload = () => resolve(img);
      img.onerror = () => reject(new Error(`${url}: could not be loaded`));
      img.src = url;
    });
  }

  async function loadModel(name, entry) {
    const info = await (await fetch(`${entry.url}info.json`)).json();
    const images = Math.ceil(info.nplanes / 3);
    const model = {
      name, info, images, type: info.type, url: entry.url,
      scale: new Float32Array(MAX_TERMS * 3), bias: new Float32Array(MAX_TERMS * 3),
      levels: [], tileSize: 0, overlap: 0, tiled: entry.levels > 0,
    };
    model.scale.set(info.materials[0].scale);
    model.bias.set(info.materials[0].bias);
    if (entry.levels > 0) {
      const dzi = await (await fetch(`${entry.url}plane_0.dzi`)).text();
      const xml = new DOMParser().parseFromString(dzi, "application/xml").documentElement;
      model.tileSize = Number(xml.getAttribute("TileSize"));
      model.overlap = Number(xml.getAttribute("Overlap"));
      // Level sizes as the export halves them: floored, a side of 1 kept.
      let [w, h] = [info.width, info.height];
      for (let level = entry.levels - 1; level >= 0; level--) {
        model.levels[level] = [w, h];
        w = Math.max(1, Math.floor(w / 2));
        h = Math.max(1, Math.floor(h / 2));
      }
    } else {
      model.levels = [[info.width, info.height]];
      model.tileSize = Math.max(info.width, info.height);
    }
    return model;
  }

  function tileKey(model, level, col, row) {
    return `${model.name}/${level}/${col}_${row}`;
  }

  function tileUrls(model, level, col, row) {
    const urls = [];
    for (let j = 0; j < model.images; j++) {
      urls.push(model.tiled
        ? `${model.url}plane_${j}_files/${level}/${col}_${row}.${model.info.format}`
        : `${model.url}plane_${j}.${model.info.format}`);
    }
    return urls;
  }

  // The tile's pixels of its level: the inner span, and the texture span with the overlap.
  function tileSpans(model, level, col, row) {
    const [w, h] = model.levels[level];
    const t = model.tileSize;
    const o = model.overlap;
    const inner = [col * t, row * t, Math.min(w, (col + 1) * t), Math.min(h, (row + 1) * t)];
    const outer = [Math.max(0, col * t - o), Math.max(0, row * t - o),
      Math.min(w, (col + 1) * t + o), Math.min(h, (row + 1) * t + o)];
    return { inner, outer };
  }

  function requestTile(model, level, col, row) {
    const key = tileKey(model, level, col, row);
    if (state.tiles.has(key)) return state.tiles.get(key);
    const tile = { texture: null, used: state.frames };
    state.tiles.set(key, tile);
    Promise.all(tileUrls(model, level, col, row).map(loadImage)).then((images) => {
      const { outer } = tileSpans(model, level, col, row);
      tile.size = [outer[2] - outer[0], outer[3] - outer[1]];
      tile.texture = planeTexture(images, ...tile.size);
      redraw();
    }, (error) => { tile.failed = String(error); status(String(error.message || error)); });
    return tile;
  }

  // A texture array of a tile's plane images (layer j: plane_j), bytes as they are.
  function planeTexture(images, w, h) {
    const gl = state.gl;
    const texture = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D_ARRAY, texture);
    gl.texStorage3D(gl.TEXTURE_2D_ARRAY, 1, gl.RGBA8, w, h, images.length);
    gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, false);
    gl.pixelStorei(gl.UNPACK_COLORSPACE_CONVERSION_WEBGL, gl.NONE);
    images.forEach((img, j) => {
      gl.texSubImage3D(gl.TEXTURE_2D_ARRAY, 0, 0, 0, j, w, h, 1, gl.RGBA, gl.UNSIGNED_BYTE, img);
    });
    for (const [p, v] of [[gl.TEXTURE_MIN_FILTER, gl.LINEAR], [gl.TEXTURE_MAG_FILTER, gl.LINEAR],
      [gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE], [gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE]]) {
      gl.texParameteri(gl.TEXTURE_2D_ARRAY, p, v);
    }
    return texture;
  }

  // A picture the server makes per light (the captured image nearest it, or the chosen
  // method relit): one request at a time per model (a drag asks for the latest light once the
  // picture under way arrives); the last picture stays on screen meanwhile.
  function serverModel(name, info, url) {
    return {
      name, type: "image", info, images: 1, server: true, url, levels: [[info.width, info.height]],
      scale: new Float32Array(MAX_TERMS * 3).fill(1), bias: new Float32Array(MAX_TERMS * 3),
      held: { texture: null, shown: null, busy: null, ms: 0, error: null, light: null },
    };
  }

  function serverPicture(model) {
    const wanted = state.light.join(",");
    const held = model.held;
    if (held.shown !== wanted && !held.busy) {
      held.busy = wanted;
      const [x, y, z] = state.light;
      const started = performance.now();
      fetch(`${model.url}?x=${x}&y=${y}&z=${z}`).then(async (response) => {
        if (!response.ok) {
          // The server says why (its choice failed, the image is too large): show it.
          throw new Error((await response.json().catch(() => ({}))).error || "the server failed");
        }
        const light = response.headers.get("X-Light");
        const img = await createImageBitmap(await response.blob());
        if (held.texture) state.gl.deleteTexture(held.texture);
        held.texture = planeTexture([img], img.width, img.height);
        held.shown = held.busy;
        held.light = light === null ? null : Number(light);
        held.ms = performance.now() - started;
        held.busy = null;
        redraw();
      }).catch((error) => {
        held.busy = null;
        held.error = String(error.message || error);
        status(held.error);
      });
    }
    return held.shown === wanted ? 0 : 1;
  }

  function drawServer(model) {
    const gl = state.gl;
    const u = state.uniforms;
    const missing = serverPicture(model);
    if (!model.held.texture) return missing;
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D_ARRAY, model.held.texture);
    gl.uniform4f(u.rect, 0, 0, model.info.width, model.info.height);
    gl.uniform4f(u.uvRect, 0, 0, 1, 1);
    gl.drawArrays(gl.TRIANGLE_STRIP, 0, 4);
    return missing;
  }

  function evict() {
    if (state.tiles.size <= TILE_CACHE) return;
    const old = [...state.tiles.entries()].filter(([k]) => !k.includes("/0/"))
      .sort((a, b) => a[1].used - b[1].used);
    for (const [key, tile] of old.slice(0, state.tiles.size - TILE_CACHE)) {
      if (tile.texture) state.gl.deleteTexture(tile.texture);
      state.tiles.delete(key);
    }
  }

  // --- drawing ------------------------------------------------------------------------------
  function compile() {
    const gl = state.gl;
    const shader = (type, source) => {
      const s = gl.createShader(type);
      gl.shaderSource(s, source);
      gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
      return s;
    };
    const program = gl.createProgram();
    gl.attachShader(program, shader(gl.VERTEX_SHADER, VERTEX));
    gl.attachShader(program, shader(gl.FRAGMENT_SHADER, FRAGMENT));
    gl.linkProgram(program);
    if (!gl.getProgramParameter(program, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(program));
    state.program = program;
    for (const name of ["rect", "uvRect", "view", "canvas", "image", "planes", "normals", "terms",
      "weights", "scale", "bias", "mode", "light", "specular"]) {
      state.uniforms[name] = gl.getUniformLocation(program, name);
    }
    const buffer = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, buffer);
    gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([0, 0, 1, 0, 0, 1, 1, 1]), gl.STATIC_DRAW);
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    const at = gl.getAttribLocation(program, "corner");
    gl.enableVertexAttribArray(at);
    gl.vertexAttribPointer(at, 2, gl.FLOAT, false, 0, 0);
  }

  // The level whose pixels are no smaller than the screen's at this zoom.
  function levelFor(model, scale) {
    const finest = model.levels.length - 1;
    const coarser = Math.floor(Math.log2(1 / Math.max(scale, 1e-9)));
    return Math.min(finest, Math.max(0, finest - Math.max(0, coarser)));
  }

  function drawTiles(model, level, bounds, width, height, view) {
    const gl = state.gl;
    const u = state.uniforms;
    const [w, h] = model.levels[level];
    const fx = model.info.width / w;
    const fy = model.info.height / h;
    const t = model.tileSize;
    const cols = [Math.max(0, Math.floor(bounds[0] / fx / t)), Math.min(Math.ceil(w / t) - 1, Math.floor(bounds[2] / fx / t))];
    const rows = [Math.max(0, Math.floor(bounds[1] / fy / t)), Math.min(Math.ceil(h / t) - 1, Math.floor(bounds[3] / fy / t))];
    let missing = 0;
    for (let row = rows[0]; row <= rows[1]; row++) {
      for (let col = cols[0]; col <= cols[1]; col++) {
        const tile = requestTile(model, level, col, row);
        tile.used = state.frames;
        if (!tile.texture) { missing += 1; continue; }
        const { inner, outer } = tileSpans(model, level, col, row);
        const [tw, th] = tile.size;
        gl.activeTexture(gl.TEXTURE0);
        gl.bindTexture(gl.TEXTURE_2D_ARRAY, tile.texture);
        gl.uniform4f(u.rect, inner[0] * fx, inner[1] * fy, inner[2] * fx, inner[3] * fy);
        gl.uniform4f(u.uvRect, (inner[0] - outer[0]) / tw, (inner[1] - outer[1]) / th,
          (inner[2] - outer[0]) / tw, (inner[3] - outer[1]) / th);
        gl.drawArrays(gl.TRIANGLE_STRIP, 0, 4);
      }
    }
    return missing;
  }

  // Draw the image in a target of width x height through `view` (image px -> target px).
  function drawImage(width, height, view, finest) {
    const gl = state.gl;
    const u = state.uniforms;
    const model = state.model;
    gl.viewport(0, 0, width, height);
    gl.clearColor(0.067, 0.067, 0.067, 1);
    gl.clear(gl.COLOR_BUFFER_BIT);
    gl.useProgram(state.program);
    gl.uniform3f(u.view, view.scale, view.x, view.y);
    gl.uniform2f(u.canvas, width, height);
    gl.uniform2f(u.image, model.info.width, model.info.height);
    gl.uniform1i(u.planes, 0);
    gl.uniform1i(u.normals, 1);
    gl.activeTexture(gl.TEXTURE1);
    gl.bindTexture(gl.TEXTURE_2D, state.normals);
    const w = weights(model.type, state.light);
    const terms = model.info.nplanes / 3;
    gl.uniform1i(u.terms, terms);
    gl.uniform1fv(u.weights, new Float32Array([...w.slice(0, terms), ...new Array(MAX_TERMS - terms).fill(0)]));
    gl.uniform3fv(u.scale, model.scale);
    gl.uniform3fv(u.bias, model.bias);
    gl.uniform1i(u.mode, state.mode);
    gl.uniform3f(u.light, ...state.light);
    gl.uniform3f(u.specular, ...state.specular);
    // The part of the image in view (image pixels).
    const bounds = [-view.x / view.scale, -view.y / view.scale,
      (width - view.x) / view.scale, (height - view.y) / view.scale];
    if (model.server) return drawServer(model);
    const level = finest ? model.levels.length - 1 : levelFor(model, view.scale);
    let missing = 0;
    if (level > 0) drawTiles(model, 0, bounds, width, height, view);  // under it, while loading
    missing = drawTiles(model, level, bounds, width, height, view);
    evict();
    return missing;
  }

  function redraw() {
    if (state.pending || !state.ready) return;
    state.pending = true;
    requestAnimationFrame(() => {
      state.pending = false;
      const canvas = $("light-canvas");
      const started = performance.now();
      state.frames += 1;
      const missing = drawImage(canvas.width, canvas.height, state.view, false);
      state.gl.finish();
      const ms = performance.now() - started;
      if (missing === 0) {
        state.drawn += 1;
        document.body.dataset.lightFrame = String(state.drawn);
      }
      showLight(ms, missing);
    });
  }

  // --- controls -----------------------------------------------------------------------------
  function status(text) {
    $("light-status").textContent = text;
  }

  function showLight(ms, missing) {
    const [x, y, z] = state.light;
    const azimuth = (Math.atan2(y, x) * 180 / Math.PI + 360) % 360;
    const elevation = Math.asin(Math.min(1, z)) * 180 / Math.PI;
    $("light-angles").textContent = `azimuth ${azimuth.toFixed(1)}°, elevation ${elevation.toFixed(1)}°`;
    const zoom = state.view.scale >= 1 ? `×${state.view.scale.toFixed(1)}` : `1/${(1 / state.view.scale).toFixed(1)}`;
    const loading = missing ? `, loading ${missing} tile${missing > 1 ? "s" : ""}` : "";
    if (state.model.name === "captured") {
      const held = state.model.held;
      const which = held.light === null ? "" : ` (light ${held.light + 1} of ${state.lights})`;
      const fits = state.fitsReady ? "" : ` — the fits: ${state.serverStatus || "waiting"}`;
      status(`the captured image nearest the light${which}, zoom ${zoom}${fits}`);
    } else if (state.model.server) {
      const held = state.model.held;
      const waiting = held.busy ? " — relighting on the server…" : "";
      const method = state.chosenMethod ? `${state.chosenMethod}, ` : "";
      status(`the chosen method (${method}server: ${held.ms.toFixed(0)} ms a light)${waiting}, zoom ${zoom}`);
      if (held.busy && !state.chosenMethod) pollChosen();
    } else {
      status(`${state.model.name.toUpperCase()} on the GPU — ${ms.toFixed(1)} ms a frame, zoom ${zoom}${loading}`);
    }
    drawPad();
  }

  // While the server chooses the method (the first light), say what it is doing.
  async function pollChosen() {
    if (state.polling) return;
    state.polling = true;
    while (state.models.chosen.held.busy && !state.chosenMethod) {
      const chosen = (await (await fetch("api/light")).json()).chosen;
      if (chosen.method) state.chosenMethod = chosen.method;
      else status(`server: ${chosen.status}…`);
      await new Promise((r) => setTimeout(r, 500));
    }
    state.polling = false;
  }

  function setLight(x, y) {
    const r = Math.hypot(x, y);
    // On the rim the light grazes; past it, it is held on the rim (no light from below).
    const k = r > 0.999 ? 0.999 / r : 1;
    x *= k; y *= k;
    state.light = [x, y, Math.sqrt(Math.max(0, 1 - x * x - y * y))];
    redraw();
  }

  function drawPad() {
    const pad = $("light-pad");
    const g = pad.getContext("2d");
    const r = pad.width / 2 - 4;
    const c = pad.width / 2;
    g.clearRect(0, 0, pad.width, pad.height);
    g.fillStyle = "#222";
    g.strokeStyle = "#555";
    g.beginPath(); g.arc(c, c, r, 0, 2 * Math.PI); g.fill(); g.stroke();
    for (const e of [30, 60]) {  // elevation rings
      g.beginPath(); g.arc(c, c, r * Math.cos(e * Math.PI / 180), 0, 2 * Math.PI); g.stroke();
    }
    const [x, y] = state.light;
    g.fillStyle = "#fd5";
    g.beginPath(); g.arc(c + x * r, c - y * r, 6, 0, 2 * Math.PI); g.fill();
  }

  function padLight(event, element) {
    const box = element.getBoundingClientRect();
    const x = ((event.clientX - box.left) / box.width) * 2 - 1;
    const y = 1 - ((event.clientY - box.top) / box.height) * 2;
    setLight(x, y);
  }

  function fit() {
    const canvas = $("light-canvas");
    const info = state.model.info;
    const scale = Math.min(canvas.width / info.width, canvas.height / info.height);
    state.view = { scale, x: (canvas.width - info.width * scale) / 2, y: (canvas.height - info.height * scale) / 2 };
    redraw();
  }

  function sizeCanvas() {
    const canvas = $("light-canvas");
    const info = state.model.info;
    // Beside the pad's column (14em and the gap), within the page's left column.
    const room = (canvas.parentElement.clientWidth || 860) - $("light-side").offsetWidth - 20;
    const width = Math.max(320, Math.min(960, room));
    const height = Math.round(Math.min(640, width * info.height / info.width));
    canvas.width = width;
    canvas.height = Math.max(200, height);
  }

  function wire() {
    const canvas = $("light-canvas");
    const pad = $("light-pad");
    const drag = (element, onMove) => {
      element.addEventListener("pointerdown", (down) => {
        element.setPointerCapture(down.pointerId);
        const start = { x: down.clientX, y: down.clientY, view: { ...state.view } };
        const move = (e) => onMove(e, start, down);
        const up = () => {
          element.removeEventListener("pointermove", move);
          element.removeEventListener("pointerup", up);
        };
        element.addEventListener("pointermove", move);
        element.addEventListener("pointerup", up);
        onMove(down, start, down);
      });
    };
    drag(pad, (e) => padLight(e, pad));
    drag(canvas, (e, start, down) => {
      if (down.shiftKey || down.button === 1) {
        const ratio = canvas.width / canvas.getBoundingClientRect().width;
        state.view = { ...start.view, x: start.view.x + (e.clientX - start.x) * ratio, y: start.view.y + (e.clientY - start.y) * ratio };
        redraw();
      } else {
        padLight(e, canvas);
      }
    });
    canvas.addEventListener("wheel", (event) => {
      event.preventDefault();
      const box = canvas.getBoundingClientRect();
      const ratio = canvas.width / box.width;
      const px = (event.clientX - box.left) * ratio;
      const py = (event.clientY - box.top) * ratio;
      const factor = Math.exp(-event.deltaY * 0.002);
      const scale = Math.min(64, Math.max(0.01, state.view.scale * factor));
      const k = scale / state.view.scale;
      state.view = { scale, x: px - (px - state.view.x) * k, y: py - (py - state.view.y) * k };
      redraw();
    }, { passive: false });
    canvas.addEventListener("dblclick", fit);
    $("light-model").addEventListener("change", (e) => {
      state.model = state.models[e.target.value];
      state.chose = true;
      redraw();
    });
    $("light-mode").addEventListener("change", (e) => {
      state.mode = Number(e.target.value);
      $("light-specular").disabled = state.mode !== 2;
      redraw();
    });
    for (const [id, index] of [["spec-diffuse", 0], ["spec-gain", 1], ["spec-exponent", 2]]) {
      $(id).addEventListener("input", (e) => { state.specular[index] = Number(e.target.value); redraw(); });
    }
    $("light-zoom-1").addEventListener("click", () => {
      const canvas = $("light-canvas");
      const cx = (canvas.width / 2 - state.view.x) / state.view.scale;
      const cy = (canvas.height / 2 - state.view.y) / state.view.scale;
      state.view = { scale: 1, x: canvas.width / 2 - cx, y: canvas.height / 2 - cy };
      redraw();
    });
    $("light-fit").addEventListener("click", fit);
  }

  async function start() {
    $("light-section").hidden = false;
    const canvas = $("light-canvas");
    const gl = canvas.getContext("webgl2", { preserveDrawingBuffer: true, antialias: false });
    if (!gl) {
      status("this browser has no WebGL2: the light cannot be moved here (the panorama view below still works)");
      return;
    }
    state.gl = gl;
    status("compiling the shader…");
    compile();
    let described = await (await fetch("api/light")).json();
    // The captured images first: the light moves from the first second, among the measured
    // lights, while the server fits the models the light moves freely with.
    const info = { width: described.image.width, height: described.image.height, nplanes: 3 };
    state.lights = described.captured.lights;
    state.models.captured = serverModel("captured", info, "api/light/captured.png");
    state.models.chosen = serverModel("chosen", info, "api/light/chosen.png");
    const select = $("light-model");
    const option = (value, textContent, title, disabled = false) => Object.assign(
      document.createElement("option"), { value, textContent, title, disabled });
    select.replaceChildren(option("captured", "captured image (nearest light)",
      "no fit: the measured image whose light is nearest the one asked for"));
    state.model = state.models.captured;
    state.firstModel = "captured";
    state.normals = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, state.normals);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA8, 1, 1, 0, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array([128, 128, 255, 255]));
    const modes = [...$("light-mode").options].filter((o) => o.value !== "0");
    for (const mode of modes) { mode.disabled = true; mode.title = "waiting for the normal map (written with the fits)"; }
    wire();
    sizeCanvas();
    state.ready = true;
    setLight(0, 0);
    fit();
    // The server fits the models in the background: say what it does until they are written.
    while (described.status !== "ready") {
      if (described.status === "failed") {
        state.serverStatus = `could not be prepared: ${described.error}`;
        status(`the light view's fits could not be prepared: ${described.error}`);
        return;
      }
      state.serverStatus = `${described.status}… (${described.elapsed_s} s)`;
      redraw();
      await new Promise((r) => setTimeout(r, 400));
      described = await (await fetch("api/light")).json();
    }
    for (const [name, entry] of Object.entries(described.models)) {
      state.models[name] = await loadModel(name, entry);
    }
    const fits = Object.keys(described.models).map((name) => option(name, `${name.toUpperCase()} fit`,
      `quantised to 8 bits: ${described.models[name].rms_error} levels RMS at the measured lights`));
    const chosen = described.chosen;
    select.replaceChildren(...fits, option("chosen", "the chosen method (server)",
      chosen.unavailable || "the method rig relight --lights chooses by held-out error, relit on the server for each light (the first light waits for the choice)",
      Boolean(chosen.unavailable)), ...select.options);
    const normals = await loadImage(described.normals).catch(() => null);
    gl.bindTexture(gl.TEXTURE_2D, state.normals);
    if (normals && Math.max(normals.width, normals.height) <= gl.getParameter(gl.MAX_TEXTURE_SIZE)) {
      gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA8, gl.RGBA, gl.UNSIGNED_BYTE, normals);
      for (const mode of modes) { mode.disabled = false; mode.title = ""; }
    } else {
      for (const mode of modes) mode.title = "the normal map is larger than this GPU's textures";
    }
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
    state.fitsReady = true;
    // The first fit takes over unless the person chose a model meanwhile.
    if (!state.chose) state.model = state.models[fits[0].value];
    select.value = state.model.name;
    redraw();
  }

  // The image at its own resolution (one texel a pixel, the finest level), read back:
  // [width, height, RGBA bytes]. For tests and for saving what the page shows.
  async function snapshot() {
    const gl = state.gl;
    const { width, height } = state.model.info;
    const view = { scale: 1, x: 0, y: 0 };
    const target = gl.createTexture();
    gl.bindTexture(gl.TEXTURE_2D, target);
    gl.texStorage2D(gl.TEXTURE_2D, 1, gl.RGBA8, width, height);
    const buffer = gl.createFramebuffer();
    gl.bindFramebuffer(gl.FRAMEBUFFER, buffer);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, target, 0);
    try {
      for (let attempt = 0; attempt < 600; attempt++) {
        if (drawImage(width, height, view, true) === 0) break;
        await new Promise((r) => setTimeout(r, 100));
      }
      const pixels = new Uint8Array(width * height * 4);
      gl.readPixels(0, 0, width, height, gl.RGBA, gl.UNSIGNED_BYTE, pixels);
      // GL's rows run bottom up; the image's top down.
      const rows = new Uint8Array(pixels.length);
      for (let row = 0; row < height; row++) {
        rows.set(pixels.subarray(row * width * 4, (row + 1) * width * 4), (height - 1 - row) * width * 4);
      }
      return [width, height, Array.from(rows)];
    } finally {
      gl.bindFramebuffer(gl.FRAMEBUFFER, null);
      gl.deleteFramebuffer(buffer);
      gl.deleteTexture(target);
      redraw();
    }
  }

  return { start, state, setLight, snapshot, weights };
})();
