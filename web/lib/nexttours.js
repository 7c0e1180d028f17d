// The next public booked tours (docs/server.md, "Bookings"): "Spanish tour at 14:00, meet at the
// Entrance hall", in the page's language. The server gives the names already in that language
// (GET /api/bookings/next, the robot's screen); the tour's language is named here
// (`lang_<code>` in /lang/*.json, else its code). The visitor panel and the robot's touch
// screen both show them with this.

/** One line per tour: its name, then its language, time and meeting point. */
export function nextTourLines(t, tours) {
  return (tours ?? []).map((tour) => ({
    id: `${tour.id}@${tour.at}`,
    name: tour.name,
    line: t("next_tour_line", {
      language: t(`lang_${tour.lang}`) === `lang_${tour.lang}` ? tour.lang : t(`lang_${tour.lang}`),
      time: tour.time,
      place: tour.meeting_point,
    }),
  }));
}
