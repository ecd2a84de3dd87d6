/**
 * Init script for the frame-rate test: wraps Plotly.react / Plotly.newPlot when Plotly.js
 * defines window.Plotly and the WebSocket, and records (performance.now()) every draw of the
 * map and every stream frame in window.__rec.
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
  const Native = window.WebSocket;
  window.WebSocket = class extends Native {
    constructor(...args) {
      super(...args);
      this.addEventListener("message", (e) => {
        try {
          const type = JSON.parse(e.data).type;
          if (type === "delta" || type === "full") rec.frames.push(performance.now());
        } catch {
          /* not JSON */
        }
      });
    }
  };
})();
