// The API docs page (/docs): Swagger UI from web/vendor/swagger-ui (no CDN, works offline) on
// the server's /openapi.json. The bundle is a classic script: it sets window.SwaggerUIBundle.
const { SwaggerUIBundle } = window;

window.ui = SwaggerUIBundle({
  url: "/openapi.json",
  dom_id: "#swagger-ui",
  layout: "BaseLayout",
  deepLinking: true,
  // Tags start folded: with every tag open, this Swagger UI drew only the first nine of the
  // API's 133 operations (it draws them all up to 128); a tag opens on a click.
  docExpansion: "none",
  validatorUrl: null, // the badge would ask validator.swagger.io: nothing leaves this server
  showExtensions: true,
  showCommonExtensions: true,
  presets: [SwaggerUIBundle.presets.apis, SwaggerUIBundle.SwaggerUIStandalonePreset],
});
