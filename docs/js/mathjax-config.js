// MathJax settings for pymdownx.arithmatex (generic mode): \( \) inline, \[ \] display.
// The site bundles MathJax's tex-svg-full.js (docs/hooks/offline.py): every TeX extension is in
// that file and SVG output needs no fonts, so nothing is loaded from elsewhere.
window.MathJax = {
  tex: { inlineMath: [["\\(", "\\)"]], displayMath: [["\\[", "\\]"]], processEscapes: true, processEnvironments: true },
  svg: { fontCache: "global" },
  options: { ignoreHtmlClass: ".*|", processHtmlClass: "arithmatex" },
};
