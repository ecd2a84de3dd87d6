/**
 * WCAG 2.1 contrast of what the page shows (run with page.evaluate; see test_contrast.py).
 * Returns {checked, failures}: every visible text (HTML, SVG labels, control values and
 * placeholders, ::before/::after labels) against the background it is drawn on, and the
 * borders of text fields and selects against their surroundings.
 */
() => {
  const parse = (c) => {
    if (!c || c === "transparent") return [0, 0, 0, 0];
    let m = /^rgba?\(([^)]+)\)$/.exec(c);
    if (m) {
      const p = m[1]
        .split(/[\s,/]+/)
        .filter(Boolean)
        .map(Number);
      return [p[0], p[1], p[2], p.length > 3 ? p[3] : 1];
    }
    m = /^color\(srgb ([^)]+)\)$/.exec(c);
    if (m) {
      const p = m[1]
        .split(/[\s/]+/)
        .filter(Boolean)
        .map(Number);
      return [p[0] * 255, p[1] * 255, p[2] * 255, p.length > 3 ? p[3] : 1];
    }
    return null;
  };
  const over = (top, bottom) => {
    const a = top[3] + bottom[3] * (1 - top[3]);
    if (a === 0) return [0, 0, 0, 0];
    return [0, 1, 2]
      .map((i) => (top[i] * top[3] + bottom[i] * bottom[3] * (1 - top[3])) / a)
      .concat([a]);
  };
  const lum = ([r, g, b]) => {
    const f = (v) => {
      v /= 255;
      return v <= 0.04045 ? v / 12.92 : ((v + 0.055) / 1.055) ** 2.4;
    };
    return 0.2126 * f(r) + 0.7152 * f(g) + 0.0722 * f(b);
  };
  const ratio = (a, b) => {
    const [x, y] = [lum(a), lum(b)].sort((p, q) => q - p);
    return (x + 0.05) / (y + 0.05);
  };
  /** The colour behind el: its own and its ancestors' backgrounds, composited on the canvas. */
  const backdrop = (el, own = null) => {
    const layers = own ? [own] : [];
    for (let n = el; n && n.nodeType === 1; n = n.parentElement) {
      const bg = parse(getComputedStyle(n).backgroundColor);
      if (bg && bg[3] > 0) layers.push(bg);
      if (bg && bg[3] >= 1) break;
    }
    let c = [255, 255, 255, 1];
    for (const layer of layers.reverse()) c = over(layer, c);
    return c;
  };
  const faded = (el) => {
    for (let n = el; n && n.nodeType === 1; n = n.parentElement) {
      const cs = getComputedStyle(n);
      if (Number(cs.opacity) < 1 || cs.visibility === "hidden") return true;
      if (n.matches(":disabled, [aria-disabled=true]")) return true;
    }
    return false;
  };
  const shown = (el) => {
    if (!el.isConnected || el.closest("[hidden], .hoverlayer, .visually-hidden, noscript"))
      return false;
    const r = el.getBoundingClientRect();
    return r.width > 0 && r.height > 0 && r.bottom > 0 && r.right > 0;
  };
  const large = (cs) => {
    const px = parseFloat(cs.fontSize);
    return px >= 24 || (px >= 18.66 && Number(cs.fontWeight) >= 700);
  };
  const failures = [];
  let checked = 0;
  const check = (el, fg, bg, cs, what, min = null) => {
    if (!fg || fg[3] === 0) return;
    const color = over(fg, bg);
    const need = min ?? (large(cs) ? 3 : 4.5);
    const r = ratio(color, bg);
    checked += 1;
    if (r + 1e-6 < need) {
      failures.push({
        what,
        ratio: Math.round(r * 100) / 100,
        need,
        fg: cs.color,
        text: (el.textContent || el.value || el.placeholder || "").trim().slice(0, 40),
        el:
          el.tagName.toLowerCase() +
          (el.className && typeof el.className === "string"
            ? "." + el.className.trim().split(/\s+/).join(".")
            : ""),
      });
    }
  };
  for (const el of document.querySelectorAll("body *")) {
    if (!shown(el) || faded(el)) continue;
    const cs = getComputedStyle(el);
    if (el instanceof SVGElement) {
      if (el.tagName === "text" && el.textContent.trim()) {
        const host = el.closest(".main-svg")?.parentElement ?? el.ownerSVGElement;
        check(el, parse(cs.fill), backdrop(host), cs, "svg text");
      }
      continue;
    }
    const ownText = [...el.childNodes].some((n) => n.nodeType === 3 && n.textContent.trim());
    if (ownText) check(el, parse(cs.color), backdrop(el), cs, "text");
    if (
      el.matches(
        "input:not([type=checkbox]):not([type=radio]):not([type=range]):not([type=file]), select, textarea",
      )
    ) {
      if (el.value) check(el, parse(cs.color), backdrop(el), cs, "value");
      if (el.placeholder && !el.value)
        check(
          el,
          parse(getComputedStyle(el, "::placeholder").color),
          backdrop(el),
          cs,
          "placeholder",
        );
      // The control's edge against what surrounds it.
      check(el, parse(cs.borderTopColor), backdrop(el.parentElement), cs, "control border", 3);
    }
    for (const pseudo of ["::before", "::after"]) {
      const ps = getComputedStyle(el, pseudo);
      if (
        !/^"[^"]*[\p{L}\p{N}][^"]*"$/u.test(ps.content) ||
        Number(ps.opacity) < 1 ||
        ps.display === "none"
      )
        continue;
      check(el, parse(ps.color), backdrop(el, parse(ps.backgroundColor)), ps, `text ${pseudo}`);
    }
  }
  return { checked, failures };
};
