"""People's accounts: passwords, sign-in sessions in a cookie, the admins' accounts API, the
audit trail of what people do (docs/security.md, "Accounts")."""
