// What the pages put on `window`: the browser tests' handles on a page's state (and the
// benchmarks'), and the API docs' classic-script bundle. Checked names, any values.
interface Window {
  /** web/nets/main.js: the RoboGraph editor's state, for the browser tests. */
  guidebotNets: any;
  /** web/admin/console.js, web/config/editor.js: the few readings a test or benchmark cannot
   * take through the page (map latencies, a redraw mid-drag, plan coordinates, background saves). */
  guidebotProbe: any;
  /** web/visitor/main.js: the captions shown and how late each came (tests, the console). */
  captionsShown: object[];
  /** web/vendor/swagger-ui: the bundle's global (web/api-docs/main.js). */
  SwaggerUIBundle: any;
  /** web/api-docs/main.js: the Swagger UI instance. */
  ui: any;
}
