// REST client with the bearer token. Every failure becomes an ApiError whose message is written
// for the person in front of the page (401: the token; 403: the role; 422: what is wrong).

export class ApiError extends Error {
  /** `reason`: the answer's machine-readable why, when it has one ("emergency": a fire alarm
   * holds the service, docs/emergency.md). */
  constructor(status, message, detail = null, reason = null) {
    super(message);
    this.status = status;
    this.detail = detail;
    this.reason = reason;
  }
}

function describe(status, detail) {
  const text = typeof detail === "string" ? detail : Array.isArray(detail)
    ? detail.map((d) => d.msg ?? d.message ?? JSON.stringify(d)).join("; ")
    : detail ? JSON.stringify(detail) : "";
  if (status === 401) return "You are signed out (the session ended, or the token was not accepted): sign in again.";
  if (status === 403) return `Not allowed for your role: ${text || "forbidden"}.`;
  if (status === 404) return text ? `Not found: ${text}.` : "Not found.";
  if (status === 409) return `Refused: ${text}.`;
  if (status === 422) return `Invalid request: ${text}.`;
  if (status === 429) return "Too many requests: wait a moment and try again.";
  return `The server answered ${status}${text ? `: ${text}` : ""}.`;
}

export class Api extends EventTarget {
  /**
   * @param {() => string | null} getToken
   * @param {() => Record<string, string>} [getHeaders] more headers for every call (the visitor
   *   panel's device id)
   */
  constructor(getToken, getHeaders = () => ({})) {
    super();
    this.getToken = getToken;
    this.getHeaders = getHeaders;
  }

  async request(method, path, body = undefined) {
    /** @type {Record<string, string>} */
    const headers = { Accept: "application/json", ...this.getHeaders() };
    const token = this.getToken();
    if (token) headers.Authorization = `Bearer ${token}`;
    if (body !== undefined) headers["Content-Type"] = "application/json";
    let response;
    try {
      response = await fetch(path, {
        method,
        headers,
        body: body === undefined ? undefined : JSON.stringify(body),
      });
    } catch {
      throw new ApiError(0, "The server cannot be reached: check the network.");
    }
    if (!response.ok) {
      let detail = null;
      let reason = null;
      try {
        const body = await response.json();
        detail = body.detail;
        reason = typeof body.reason === "string" ? body.reason : null;
      } catch {
        detail = null;
      }
      const error = new ApiError(response.status, describe(response.status, detail), detail, reason);
      if (response.status === 401 || response.status === 403) {
        this.dispatchEvent(new CustomEvent("denied", { detail: error }));
      }
      throw error;
    }
    const type = response.headers.get("content-type") ?? "";
    if (type.includes("application/json")) return response.json();
    return response.blob();
  }

  get(path) {
    return this.request("GET", path);
  }

  post(path, body = {}) {
    return this.request("POST", path, body);
  }

  put(path, body) {
    return this.request("PUT", path, body);
  }

  delete(path) {
    return this.request("DELETE", path);
  }
}
