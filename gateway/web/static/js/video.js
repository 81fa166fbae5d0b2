// The live video preview (issue #36): lists the gateway's videos (GET /api/video) and plays a running one
// from the WebSocket /api/video?id=… (an MP4 init segment, then fragments) through Media Source Extensions.
// Self-contained: its own panel, its own connection; the rest of the console does not know it.
import { get } from "./api.js";

const panel = document.getElementById("video");
const list = document.getElementById("video-list");
const player = document.getElementById("video-player");
const note = document.getElementById("video-note");
let current = null; // { id, ws, source, buffer, queue }

function codecOf(init) {
  // "avc1.PPCCLL" from the avcC box of the init segment (profile, compatibility, level)
  for (let i = 4; i + 7 < init.length; i++) {
    if (init[i] === 0x61 && init[i + 1] === 0x76 && init[i + 2] === 0x63 && init[i + 3] === 0x43) {
      const hex = (b) => b.toString(16).padStart(2, "0");
      return `avc1.${hex(init[i + 5])}${hex(init[i + 6])}${hex(init[i + 7])}`;
    }
  }
  return "avc1.42e01f";
}

function stop() {
  if (current && current.ws) current.ws.close();
  current = null;
  player.removeAttribute("src");
  player.load();
}

function pump() {
  const c = current;
  if (!c || !c.buffer || c.buffer.updating || c.queue.length === 0) return;
  c.buffer.appendBuffer(c.queue.shift());
  const ranges = c.buffer.buffered;
  if (ranges.length > 0) {
    const end = ranges.end(ranges.length - 1);
    if (end - player.currentTime > 1.0) player.currentTime = Math.max(0, end - 0.2); // keep to the live edge
  }
}

function play(id) {
  stop();
  if (!id) return;
  const c = { id, ws: null, source: new MediaSource(), buffer: null, queue: [] };
  current = c;
  player.src = URL.createObjectURL(c.source);
  c.source.addEventListener("sourceopen", () => {
    const scheme = location.protocol === "https:" ? "wss:" : "ws:";
    c.ws = new WebSocket(`${scheme}//${location.host}/api/video?id=${encodeURIComponent(id)}`);
    c.ws.binaryType = "arraybuffer";
    c.ws.onmessage = (event) => {
      const bytes = new Uint8Array(event.data);
      if (!c.buffer) {
        c.buffer = c.source.addSourceBuffer(`video/mp4; codecs="${codecOf(bytes)}"`);
        c.buffer.mode = "sequence";
        c.buffer.addEventListener("updateend", pump);
      }
      c.queue.push(bytes);
      pump();
      player.play().catch(() => {});
    };
    c.ws.onclose = () => {
      if (current === c) {
        note.textContent = "stream ended; retrying";
        setTimeout(() => current === c && play(id), 1000);
      }
    };
    note.textContent = "";
  });
}

async function refresh() {
  if (!panel) return;
  let videos = [];
  try {
    videos = (await get("/api/video")).videos || [];
  } catch {
    panel.hidden = true;
    return;
  }
  panel.hidden = videos.length === 0;
  const chosen = list.value;
  list.replaceChildren(new Option("— choose a running video —", ""));
  for (const v of videos) {
    const option = new Option(`${v.video_id}${v.live ? " (live)" : ""}`, v.video_id);
    option.disabled = !v.live;
    list.add(option);
  }
  list.value = chosen;
}

if (panel) {
  list.addEventListener("change", () => play(list.value));
  refresh();
  setInterval(refresh, 3000);
}
