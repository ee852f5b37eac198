// The live preview: shows each pass the server sends, turns drags, wheel turns and clicks into
// camera moves and dropped spheres. The server renders; the page only displays.
"use strict";

const canvas = document.getElementById("preview");
const context = canvas.getContext("2d");
const status = document.getElementById("status");
const materialPicker = document.getElementById("material");
const radius = document.getElementById("radius");
const renderButton = document.getElementById("render");
const cancelButton = document.getElementById("cancel");
const progress = document.getElementById("progress");
const pngLink = document.getElementById("png");
const MAX_PREVIEW_WIDTH = 960;

let camera = null; // {position, look_at, up, fov}
let settings = null;
let orbit = null; // {yaw, pitch, distance} of position about look_at
let cameraQueued = false;

const showRadius = () => {
  document.getElementById("radius-value").textContent = Number(radius.value).toFixed(2);
};
radius.addEventListener("input", showRadius);
showRadius();

const connection = openSocket("/ws/preview", onMessage, (text, isError) =>
  setStatus(status, text, isError)
);

function onMessage(message, blob) {
  if (message.type === "scene") {
    camera = message.camera;
    settings = message.render;
    orbit = toOrbit(camera);
    materialPicker.replaceChildren(
      ...message.materials.map((name) => new Option(name, name, false, name === "glass"))
    );
    renderButton.textContent = `Render full size (${settings.width}×${settings.height}, ` +
      `${settings.spp} spp)`;
    document.getElementById("hint").textContent =
      `${message.spheres} spheres · converges to embree-rt render's ${settings.spp} spp`;
    sendSize();
  } else if (message.type === "pass") {
    showPass(message, blob);
  } else if (message.type === "dropped") {
    if (!message.placed) setStatus(status, "that click did not land on the floor", true);
  } else if (message.type === "progress") {
    progress.hidden = false;
    progress.value = message.done / message.total;
  } else if (message.type === "rendered") {
    renderFinished();
    pngLink.href = URL.createObjectURL(blob);
    pngLink.download = "embree_rt.png";
    pngLink.hidden = false;
    setStatus(status, `rendered ${message.width}×${message.height} at ${message.spp} spp in ` +
      `${message.seconds} s`);
  } else if (message.type === "render_cancelled") {
    renderFinished();
    setStatus(status, "full-size render cancelled");
  } else if (message.type === "scene_toml") {
    download(new Blob([message.text], { type: "application/toml" }), "scene.toml");
  } else if (message.type === "error") {
    setStatus(status, message.message, true);
    if (message.message.startsWith("render")) renderFinished();
  }
}

function sendSize() {
  const width = Math.min(MAX_PREVIEW_WIDTH, canvas.parentElement.clientWidth - 2);
  const height = Math.max(8, Math.round((width * settings.height) / settings.width));
  canvas.width = width;
  canvas.height = height;
  context.fillStyle = "#05070a";
  context.fillRect(0, 0, width, height);
  connection.send({ type: "size", width, height });
}

async function showPass(message, blob) {
  const bitmap = await createImageBitmap(blob);
  if (bitmap.width === canvas.width && bitmap.height === canvas.height) {
    context.drawImage(bitmap, 0, 0);
  }
  bitmap.close();
  canvas.dataset.pass = `${message.pass}/${message.of}`;
  setStatus(status, `pass ${message.pass} of ${message.of} · ${message.ms} ms` +
    (message.pass === message.of ? " · converged" : ""));
}

// -- camera: orbit about look_at, dolly along the view ---------------------------------------

function toOrbit(cam) {
  const [dx, dy, dz] = cam.position.map((c, k) => c - cam.look_at[k]);
  const distance = Math.hypot(dx, dy, dz);
  return { yaw: Math.atan2(dx, dz), pitch: Math.asin(dy / distance), distance };
}

function moveCamera() {
  const { yaw, pitch, distance } = orbit;
  const [x, y, z] = camera.look_at;
  camera.position = [
    x + distance * Math.cos(pitch) * Math.sin(yaw),
    y + distance * Math.sin(pitch),
    z + distance * Math.cos(pitch) * Math.cos(yaw),
  ];
  if (!cameraQueued) {
    cameraQueued = true;
    requestAnimationFrame(() => {
      cameraQueued = false;
      connection.send({ type: "camera", position: camera.position, look_at: camera.look_at });
    });
  }
}

let drag = null;
canvas.addEventListener("pointerdown", (event) => {
  if (event.button !== 0 || camera === null) return;
  drag = { x: event.clientX, y: event.clientY, moved: false };
  canvas.setPointerCapture(event.pointerId);
});
canvas.addEventListener("pointermove", (event) => {
  if (drag === null) return;
  const dx = event.clientX - drag.x;
  const dy = event.clientY - drag.y;
  if (!drag.moved && Math.hypot(dx, dy) < 4) return;
  drag.moved = true;
  canvas.classList.add("dragging");
  drag.x = event.clientX;
  drag.y = event.clientY;
  orbit.yaw -= dx * 0.008;
  orbit.pitch = Math.min(1.45, Math.max(-1.45, orbit.pitch + dy * 0.006));
  moveCamera();
});
canvas.addEventListener("pointerup", (event) => {
  if (drag === null) return;
  const clicked = !drag.moved;
  drag = null;
  canvas.classList.remove("dragging");
  if (!clicked) return;
  const box = canvas.getBoundingClientRect();
  connection.send({
    type: "drop",
    x: ((event.clientX - box.left) * canvas.width) / box.width,
    y: ((event.clientY - box.top) * canvas.height) / box.height,
    radius: Number(radius.value),
    material: materialPicker.value,
  });
});
canvas.addEventListener(
  "wheel",
  (event) => {
    if (camera === null) return;
    event.preventDefault();
    orbit.distance = Math.min(500, Math.max(0.3, orbit.distance * Math.exp(event.deltaY * 0.001)));
    moveCamera();
  },
  { passive: false }
);

// -- buttons ---------------------------------------------------------------------------------

document.getElementById("download-scene").addEventListener("click", () => {
  connection.send({ type: "scene_toml" });
});
renderButton.addEventListener("click", () => {
  renderButton.disabled = true;
  cancelButton.hidden = false;
  pngLink.hidden = true;
  progress.value = 0;
  progress.hidden = false;
  connection.send({ type: "render" });
});
cancelButton.addEventListener("click", () => connection.send({ type: "cancel_render" }));

function renderFinished() {
  renderButton.disabled = false;
  cancelButton.hidden = true;
  progress.hidden = true;
}

let resizing = null;
window.addEventListener("resize", () => {
  clearTimeout(resizing);
  resizing = setTimeout(() => {
    if (settings !== null) sendSize();
  }, 250);
});
