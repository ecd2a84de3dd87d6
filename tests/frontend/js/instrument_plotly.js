/**
 * Init script for the frame-rate test: wraps Plotly.react / Plotly.newPlot when Plotly.js
 * defines window.Plotly and the WebSocket, and records (performance.now()) every draw of the
 * map and every stream frame (text or binary) in window.__rec.
 */
(() => {
  const rec = { react: [], newPlot: 0, frames: [] };
  window.__rec = rec;
  let plotly;
  Object.defineProperty(window, "Plotly", {
    configurable: true,
    get() {
      return plotly;
    },
    set(P) {
      const react = P.react;
      const newPlot = P.newPlot;
      P.react = function (gd, ...rest) {
        if (gd?.dataset?.plot === "map") rec.react.push(performance.now());
        return react.call(this, gd, ...rest);
      };
      P.newPlot = function (...args) {
        rec.newPlot += 1;
        return newPlot.apply(this, args);
      };
      plotly = P;
    },
  });
  // A text frame is JSON; a binary one (frame-codec.js) has its JSON part after 12 bytes.
  const frameType = (data) => {
    if (typeof data === "string") return JSON.parse(data).type;
    const length = new DataView(data).getUint32(8, true);
    return JSON.parse(new TextDecoder().decode(new Uint8Array(data, 12, length))).frame.type;
  };
  const Native = window.WebSocket;
  window.WebSocket = class extends Native {
    constructor(...args) {
      super(...args);
      this.addEventListener("message", (e) => {
        try {
          const type = frameType(e.data);
          if (type === "delta" || type === "full") rec.frames.push(performance.now());
        } catch {
          /* not JSON */
        }
      });
    }
  };
})();
