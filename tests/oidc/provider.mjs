// A real OpenID Connect provider for the tests (node oidc-provider with its development login
// pages: any name signs in, any password): `node provider.mjs REDIRECT_URI`. It listens on a
// free port of 127.0.0.1 and prints "ready ISSUER". One client, "guidebot" (secret
// "guidebot-test-secret", authorization code with PKCE); each person's groups come from GROUPS
// below, in the ID token's "groups" claim.
import http from "node:http";
import Provider from "oidc-provider";

const [redirect] = process.argv.slice(2);
const GROUPS = { olga: ["museum-operators"], ines: ["museum-installers"], gus: ["visitors"] };

const server = http.createServer();
server.listen(0, "127.0.0.1", () => {
  const issuer = `http://localhost:${server.address().port}`;
  const provider = new Provider(issuer, {
    clients: [
      {
        client_id: "guidebot",
        client_secret: "guidebot-test-secret",
        redirect_uris: [redirect],
        grant_types: ["authorization_code"],
        response_types: ["code"],
      },
    ],
    pkce: { required: () => true },
    claims: { openid: ["sub"], profile: ["name", "preferred_username"], groups: ["groups"] },
    scopes: ["openid", "profile", "groups"],
    conformIdTokenClaims: false, // the scopes' claims in the ID token itself
    async findAccount(_ctx, id) {
      return {
        accountId: id,
        async claims() {
          const name = `${id} (from the provider)`;
          return { sub: id, preferred_username: id, name, groups: GROUPS[id] ?? [] };
        },
      };
    },
  });
  server.on("request", provider.callback());
  console.log(`ready ${issuer}`);
});
