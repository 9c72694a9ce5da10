#pragma once
// The socket API server (docs/protocol.md). One thread multiplexes every client with epoll; it
// reads the loop's snapshots from a Seqlock and hands commands to the loop through an SpscRing, so
// the real-time loop never waits for it. Clients that misbehave are cut off; they cannot stall
// others.

#include <cstddef>
#include <memory>

#include "daemon/analysis/refine/refined_view.hpp"
#include "daemon/core/commands.hpp"
#include "daemon/core/published_state.hpp"
#include "daemon/core/rt/latency_histogram.hpp"
#include "daemon/core/rt/seqlock.hpp"
#include "daemon/core/rt/spsc_ring.hpp"
#include "daemon/outputs/server/health_control.hpp"
#include "daemon/outputs/server/peer_auth.hpp"
#include "daemon/outputs/server/settings.hpp"

namespace scp::daemon::server {

class ApiServer {
 public:
  // `state`, `commands` and `refined` must outlive the server. The server is the ring's only
  // producer. `refined` is null when the refinement is disabled. `lateness` (may be null) is the
  // loop's fine lateness histogram, read lock-free for STATUS.
  ApiServer(ServerSettings settings, ServerInfo info, const rt::Seqlock<PublishedState>& state,
            CommandRing& commands, const rt::Seqlock<refine::RefinedView>* refined = nullptr,
            const rt::LatencyHistogram* lateness = nullptr);
  ~ApiServer();  // stop()s
  ApiServer(const ApiServer&) = delete;
  ApiServer& operator=(const ApiServer&) = delete;

  // The actuator's health (null, the default: the refinement is off and health requests are
  // answered with an ERROR). Before start(); must outlive the server.
  void set_health(HealthControl* health) noexcept;

  // Binds the socket (replacing a stale socket file, refusing when another live daemon answers on
  // it), applies mode and group, and spawns the server thread. Throws std::runtime_error whose
  // message names the path and the remedy.
  void start();
  // Closes every client, joins the thread and removes the socket file. Idempotent.
  void stop() noexcept;

  // Clients connected now (for tests and the daemon's own diagnostics).
  std::size_t client_count() const noexcept;
  const AuthPolicy& auth_policy() const noexcept;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace scp::daemon::server
