"""What every REST router is made of: role checks and typed services as dependencies, the
error answers (``deps``), the strict request body (``models``), the check of query parameters
(``query``). The routers themselves live with their subject (``backend/api/`` for the brain's,
each component's ``routes.py`` for its own), above this package: it imports no router."""
