// Skipped tour stops (docs/protocol.md, "Skipped stops"): a tour skips the stops only closed
// elements lead to; each skip's reason, as the server gives it ("gallery g2 closed: cleaning",
// "door d1 out of order", several joined by "; "; "steps" on a step-free tour), is put in the visitor's language here. The
// visitor panel and the robot's touch screen both show them with this.

const PART = /^(gallery|door|elevator|nodes) (.+?) (?:closed: (.*)|out of order)$/s;

/** One skip's reason in the page's language (an unknown form is shown as it came). */
export function skipReason(t, reason) {
  return String(reason ?? "")
    .split("; ")
    .filter(Boolean)
    .map((part) => {
      if (part === "steps") return t("skip_steps");
      const m = PART.exec(part);
      if (!m) return part;
      const [, word, id, words] = m;
      return words === undefined ? t(`skip_${word}_trouble`, { id }) : t(`skip_${word}`, { id, words });
    })
    .join("; ");
}

/** One line per skipped stop: its number, its place (``placeOf(skip)``) and why. */
export function skippedLines(t, skipped, placeOf) {
  return (skipped ?? []).map((s) => t("skipped_stop", { i: s.index, place: placeOf(s), why: skipReason(t, s.reason) }));
}
