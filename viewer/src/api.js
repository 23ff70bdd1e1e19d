// REST calls of the documented API (docs/service.md, openapi/openapi.json), bearer token auth.

export class ApiError extends Error {
  constructor(status, body) {
    const field = body && body.field ? ` (${body.field})` : "";
    const text = body && body.message ? body.message : `HTTP ${status}`;
    super(`${status} ${(body && body.error) || "error"}${field}: ${text}`);
    this.status = status;
    this.body = body;
  }
}

export class Api {
  constructor(baseUrl, token) {
    this.baseUrl = baseUrl.replace(/\/$/, "");
    this.token = token;
  }

  async request(method, path, body) {
    const headers = { Authorization: `Bearer ${this.token}` };
    if (body !== undefined) headers["Content-Type"] = "application/json";
    const res = await fetch(this.baseUrl + path, {
      method,
      headers,
      body: body === undefined ? undefined : JSON.stringify(body),
    });
    if (res.status === 204) return null;
    const text = await res.text();
    let data = null;
    try {
      data = text ? JSON.parse(text) : null;
    } catch (_err) {
      data = { error: "bad_response", message: text.slice(0, 200) };
    }
    if (!res.ok) throw new ApiError(res.status, data);
    return data;
  }

  scenes() { return this.request("GET", "/v1/scenes"); }
  sessions() { return this.request("GET", "/v1/sessions").then((r) => r.sessions); }
  session(id) { return this.request("GET", `/v1/sessions/${encodeURIComponent(id)}`); }
  createSession(body) { return this.request("POST", "/v1/sessions", body); }
  deleteSession(id) { return this.request("DELETE", `/v1/sessions/${encodeURIComponent(id)}`); }
  electrodes(id) {
    return this.request("GET", `/v1/sessions/${encodeURIComponent(id)}/electrodes`)
      .then((r) => r.electrodes);
  }

  streamUrl(id) {
    const url = new URL(this.baseUrl + `/v1/sessions/${encodeURIComponent(id)}/stream`);
    url.protocol = url.protocol === "https:" ? "wss:" : "ws:";
    url.searchParams.set("token", this.token); // browsers cannot set headers on a WebSocket
    return url.toString();
  }
}
