"""The service's default limits, here so that ``starnav serve``'s options can show them
without importing the web stack."""

DEFAULT_MAX_QUEUED = 100  # jobs waiting for a worker before uploads are answered 503 busy
DEFAULT_URL_DEADLINE_S = 30.0  # a whole URL fetch: connect, TLS, request, headers, body
DEFAULT_URL_FETCHES = 4  # URL fetches at once; as many again may wait a moment for a slot
