// A fork server for the project's own executables: a process that has paid its start once and
// runs each request in a fork of itself. Starting `mcstat` costs about 0.2 s here (0.33 s under
// ASan), most of it the dynamic loader resolving the symbols of the 261 libraries Debian's
// OpenImageIO pulls in; a fork of a started process costs a few milliseconds. The test suites start
// the tools some 600 times each, so their helpers (tests/tool_run.h) keep one server per tool.
//
// Nothing a user runs reaches this: a tool serves only when its parent set MCSTAT_FORK_SERVER_FD
// to a socket it passed down. The protocol (one SOCK_SEQPACKET message each way):
//   request: "CWD\0ARG0\0ARG1\0...ARGN\0", with three descriptors (SCM_RIGHTS): the worker's
//            stdin, stdout and stderr;
//   reply:   the worker's wait status (an int, as waitpid gives it).
// The worker is the server's fork: the environment, resource limits and umask are the ones the
// server started with, so the client sends a request only while its own still match.
#pragma once

#include <functional>

namespace mcstat::detail {

/// The socket a parent passed down (MCSTAT_FORK_SERVER_FD), or -1 when this process is not a fork
/// server. Removes the variable, so that the workers' environment is the parent's.
int forkServerSocket();

/// Serves requests on `socket` until the client closes it: each request runs `run(argc, argv)` in a
/// fork with the request's working folder and descriptors, and exits with what it returns.
/// Returns the server's exit status (0 when the client closed the socket).
int serveForks(int socket, const std::function<int(int, char**)>& run);

}  // namespace mcstat::detail
