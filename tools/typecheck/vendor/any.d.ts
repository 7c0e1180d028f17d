// A vendored library (web/vendor/) seen by the checker as untyped: its default export and
// namespace are `any`.
declare const library: any;
export = library;
