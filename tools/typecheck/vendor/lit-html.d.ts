// lit-html (web/vendor/lit-html/) as the pages use it, untyped for now.
export const html: any;
export const svg: any;
export const nothing: any;
export const noChange: any;
export const render: any;
export const repeat: any;
export const live: any;
export const classMap: any;
export const ifDefined: any;
export const ref: any;
export const createRef: any;
