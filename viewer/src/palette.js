// Colours of the labels: fixed for the first ones (so a label keeps its colour between scans and
// in screenshots), then spread around the hue circle. Clear of the page's dark background.

const kFixed = ['#e4572e', '#3f8efc', '#f2c14e', '#4caf50', '#b86bd8', '#26c6da', '#ff8fab', '#a1887f'];

/**
 * The colour of a label.
 * @param {number} label material id, >= 1
 * @returns {string} CSS hex colour '#rrggbb'
 */
export function labelColor(label) {
  if (label >= 1 && label <= kFixed.length) return kFixed[label - 1];
  const hue = (label * 137.508) % 360;  // golden angle: neighbours differ
  return hslToHex(hue, 0.65, 0.55);
}

function hslToHex(hue, saturation, lightness) {
  const a = saturation * Math.min(lightness, 1 - lightness);
  const channel = (n) => {
    const k = (n + hue / 30) % 12;
    const value = lightness - a * Math.max(-1, Math.min(k - 3, 9 - k, 1));
    return Math.round(255 * value).toString(16).padStart(2, '0');
  };
  return '#' + channel(0) + channel(8) + channel(4);
}
