#!/bin/sh
# redis-server with the given options, reachable from the other containers (the official image
# turns protected mode off too); any other command runs as given.
set -eu
if [ "$1" = redis-server ]; then
    shift
    exec redis-server "$@" --protected-mode no --bind 0.0.0.0
fi
exec "$@"
