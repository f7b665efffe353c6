// Where the page's camera comes from: the one module that knows the video transport. Today that
// is /ws/video: per frame a JSON "frame" message (size, sequence, the detection) and then the
// JPEG as a binary message; "status" messages say why there is none. Callers get decoded
// frames ({bitmap, meta}) and status texts; nothing else of the page depends on the transport.

import { wsUrl } from "./dom.js";

export function connectVideo({ onFrame, onStatus, retryMs = 1500 }) {
  let nextMeta = null;
  const ws = new WebSocket(wsUrl("/ws/video"));
  ws.binaryType = "arraybuffer";
  ws.onclose = () => {
    onStatus("video: reconnecting");
    setTimeout(() => connectVideo({ onFrame, onStatus, retryMs }), retryMs);
  };
  ws.onmessage = async (ev) => {
    if (typeof ev.data === "string") {
      const msg = JSON.parse(ev.data);
      if (msg.type === "frame") nextMeta = msg;
      else if (msg.type === "status") onStatus(msg.state);
      return;
    }
    const meta = nextMeta;
    const bitmap = await createImageBitmap(new Blob([ev.data], { type: "image/jpeg" }));
    onFrame({ bitmap, meta });
  };
}
