// The console's views: the tabs in their order, and what draws each. To add a view, write
// web/admin/views/<name>.js (a function of the console state that returns its template) and
// add one line to each list (docs/console.md "Structure").
import { accountsView, passkeysView } from "/admin/views/accounts.js";
import { alertsView } from "/admin/views/alerts.js";
import { bookingsView } from "/admin/views/bookings.js";
import { buildingView } from "/admin/views/building.js";
import { eventsView } from "/admin/views/events.js";
import { fleetView } from "/admin/views/fleet.js";
import { locksView } from "/admin/views/locks.js";
import { modesView } from "/admin/views/modes.js";
import { monitorView } from "/admin/views/monitor.js";
import { notificationsView } from "/admin/views/notifications.js";
import { reportsView } from "/admin/views/reports.js";
import { robotsView } from "/admin/views/robots.js";
import { tasksView } from "/admin/views/tasks.js";

/**
 * The tabs: [view id, tab label, the only role that sees it (all staff when absent)]. The map
 * is a tab too; it is drawn by web/admin/livemap.js, not from RENDER.
 * @type {ReadonlyArray<readonly [string, string, string?]>}
 */
export const VIEWS = [
  ["map", "Map"],
  ["robots", "Robots"],
  ["tasks", "Tasks"],
  ["fleet", "Fleet"],
  ["locks", "Locks"],
  ["building", "Building"],
  ["modes", "Modes"],
  ["bookings", "Bookings"],
  ["monitor", "RoboGraph monitor"],
  ["alerts", "Alerts"],
  ["events", "Event log"],
  ["reports", "Reports"],
  ["notifications", "Notifications"],
  ["accounts", "Accounts", "admin"],
];

/**
 * Each view's template, from the console state.
 * @type {Readonly<Record<string, (ui: any) => unknown>>}
 */
export const RENDER = {
  robots: robotsView,
  tasks: tasksView,
  fleet: fleetView,
  locks: locksView,
  building: buildingView,
  modes: modesView,
  bookings: bookingsView,
  monitor: monitorView,
  alerts: alertsView,
  events: eventsView,
  reports: reportsView,
  accounts: accountsView,
  notifications: notificationsView,
  passkeys: passkeysView, // from the header's "Your passkeys", not a tab
};
