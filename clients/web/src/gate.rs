//! Who may hold a connection, sans-IO: pages that presented a right token are counted apart;
//! connections that have not (yet) are bounded in all and per address, and the oldest of them
//! makes room for a new one, so idle or half-open connections never keep out a page with a
//! right token. Wrong tokens are slowed per address and logged by count, not one line each.

use std::collections::{HashMap, VecDeque};
use std::net::IpAddr;
use std::time::Duration;

/// Connections that have not authenticated, at most, in all.
pub const MAX_UNAUTHENTICATED: usize = 64;

/// Connections that have not authenticated, at most, from one address.
pub const PER_ADDRESS: usize = 32;

/// The delay before a wrong token's answer, doubled for each further one from its address (up
/// to [`MAX_FAILURE_DELAY`]) and forgotten after [`FAILURES_FORGOTTEN`] without one.
pub const FIRST_FAILURE_DELAY: Duration = Duration::from_millis(100);

/// The longest delay before a wrong token's answer.
pub const MAX_FAILURE_DELAY: Duration = Duration::from_secs(5);

/// An address without a wrong token this long starts again with no delay.
pub const FAILURES_FORGOTTEN: Duration = Duration::from_secs(60);

/// Wrong tokens are logged at most this often, by count.
pub const FAILURES_LOGGED_EVERY: Duration = Duration::from_secs(60);

/// Addresses whose failures are kept at once; past this the oldest are forgotten.
const MAX_FAILING_ADDRESSES: usize = 1024;

/// A connection's number, given by the driver.
pub type ConnId = u64;

/// What to do with a new connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Admit {
    /// Serve it.
    Accept,
    /// Serve it, and close connection `ConnId` (the oldest that has not authenticated) to
    /// make room.
    AcceptEvicting(ConnId),
}

/// One address's wrong tokens.
#[derive(Debug, Clone, Copy)]
struct Failures {
    /// In a row (since the last was forgotten).
    count: u32,
    /// The last one.
    last: Duration,
    /// Not yet logged.
    unlogged: u64,
}

/// The gate of one server.
#[derive(Debug, Default)]
pub struct Gate {
    /// Connections that have not authenticated, oldest first.
    waiting: VecDeque<(ConnId, IpAddr)>,
    failures: HashMap<IpAddr, Failures>,
    last_logged: Option<Duration>,
}

impl Gate {
    /// A new connection `id` from `address`: served, after closing the oldest connection of
    /// that address (past its share) or of all (past the total) that has not authenticated.
    pub fn handle_connect(&mut self, id: ConnId, address: IpAddr) -> Admit {
        let from_there = self.waiting.iter().filter(|(_, a)| *a == address).count();
        let evict = if from_there >= PER_ADDRESS {
            self.waiting.iter().position(|(_, a)| *a == address)
        } else if self.waiting.len() >= MAX_UNAUTHENTICATED {
            Some(0)
        } else {
            None
        };
        let evicted = evict
            .and_then(|at| self.waiting.remove(at))
            .map(|(id, _)| id);
        self.waiting.push_back((id, address));
        match evicted {
            Some(old) => Admit::AcceptEvicting(old),
            None => Admit::Accept,
        }
    }

    /// Connection `id` presented a right token: it no longer counts against anyone.
    pub fn handle_authenticated(&mut self, id: ConnId) {
        self.waiting.retain(|(waiting, _)| *waiting != id);
    }

    /// Connection `id` closed (or was answered and closed).
    pub fn handle_closed(&mut self, id: ConnId) {
        self.waiting.retain(|(waiting, _)| *waiting != id);
    }

    /// A wrong token from `address` at `now`: how long to wait before answering it.
    pub fn handle_wrong_token(&mut self, now: Duration, address: IpAddr) -> Duration {
        if !self.failures.contains_key(&address) && self.failures.len() >= MAX_FAILING_ADDRESSES {
            let oldest = self
                .failures
                .iter()
                .min_by_key(|(_, failures)| failures.last)
                .map(|(address, _)| *address);
            if let Some(oldest) = oldest {
                self.failures.remove(&oldest);
            }
        }
        let failures = self.failures.entry(address).or_insert(Failures {
            count: 0,
            last: now,
            unlogged: 0,
        });
        if now.saturating_sub(failures.last) > FAILURES_FORGOTTEN {
            failures.count = 0;
        }
        failures.count = failures.count.saturating_add(1);
        failures.last = now;
        failures.unlogged += 1;
        let doublings = failures.count.saturating_sub(1).min(16);
        FIRST_FAILURE_DELAY
            .saturating_mul(1 << doublings)
            .min(MAX_FAILURE_DELAY)
    }

    /// The wrong tokens not yet logged, by address (most first), once every
    /// [`FAILURES_LOGGED_EVERY`] (the very first at once): a log line for the driver.
    pub fn poll_log(&mut self, now: Duration) -> Option<String> {
        let due = self
            .last_logged
            .is_none_or(|last| now.saturating_sub(last) >= FAILURES_LOGGED_EVERY);
        let mut unlogged: Vec<(IpAddr, u64)> = self
            .failures
            .iter()
            .filter(|(_, failures)| failures.unlogged > 0)
            .map(|(address, failures)| (*address, failures.unlogged))
            .collect();
        if !due || unlogged.is_empty() {
            return None;
        }
        self.last_logged = Some(now);
        for failures in self.failures.values_mut() {
            failures.unlogged = 0;
        }
        unlogged.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
        let total: u64 = unlogged.iter().map(|(_, count)| count).sum();
        let listed: Vec<String> = unlogged
            .iter()
            .take(5)
            .map(|(address, count)| format!("{count} from {address}"))
            .collect();
        Some(format!(
            "{total} WebSocket{} refused for a wrong token since the last report: {}{}",
            if total == 1 { "" } else { "s" },
            listed.join(", "),
            if unlogged.len() > 5 { ", ..." } else { "" }
        ))
    }

    /// Connections that have not authenticated now.
    pub fn waiting(&self) -> usize {
        self.waiting.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::net::Ipv4Addr;

    const S: Duration = Duration::from_secs(1);

    fn ip(last: u8) -> IpAddr {
        IpAddr::V4(Ipv4Addr::new(10, 0, 0, last))
    }

    #[test]
    fn idle_connections_make_room_for_a_page_oldest_first() {
        let mut gate = Gate::default();
        // Another user's idle connections, from loopback as the page's are.
        let attacker = IpAddr::V4(Ipv4Addr::LOCALHOST);
        for id in 0..PER_ADDRESS as u64 {
            assert_eq!(gate.handle_connect(id, attacker), Admit::Accept);
        }
        // The page's connection: served, the oldest idle one closed for it.
        let page = 1000;
        assert_eq!(
            gate.handle_connect(page, attacker),
            Admit::AcceptEvicting(0)
        );
        gate.handle_authenticated(page);
        // Renewed idle connections push out only idle ones, oldest first: never the page.
        assert_eq!(gate.handle_connect(2000, attacker), Admit::Accept);
        for id in 2001..2100 {
            match gate.handle_connect(id, attacker) {
                Admit::AcceptEvicting(old) => assert!(old != page && old < id, "{old}"),
                Admit::Accept => panic!("past its share without an eviction"),
            }
        }
        assert_eq!(gate.waiting(), PER_ADDRESS);
    }

    #[test]
    fn past_the_total_the_oldest_of_all_goes_and_each_address_keeps_its_share() {
        let mut gate = Gate::default();
        let mut id = 0;
        for last in 1..=2 {
            for _ in 0..PER_ADDRESS {
                assert_eq!(gate.handle_connect(id, ip(last)), Admit::Accept);
                id += 1;
            }
        }
        assert_eq!(gate.waiting(), MAX_UNAUTHENTICATED);
        // A third address: the oldest of all makes room.
        assert_eq!(gate.handle_connect(id, ip(3)), Admit::AcceptEvicting(0));
        gate.handle_closed(5);
        assert_eq!(gate.waiting(), MAX_UNAUTHENTICATED - 1);
        assert_eq!(gate.handle_connect(id + 1, ip(3)), Admit::Accept);
    }

    #[test]
    fn wrong_tokens_are_slowed_per_address_and_logged_by_count() {
        let mut gate = Gate::default();
        let delays: Vec<Duration> = (0..8)
            .map(|i| gate.handle_wrong_token(S * i, ip(1)))
            .collect();
        assert_eq!(delays[0], FIRST_FAILURE_DELAY);
        assert_eq!(delays[1], FIRST_FAILURE_DELAY * 2);
        assert_eq!(delays[7], MAX_FAILURE_DELAY);
        // Another address is not slowed by the first one's guesses.
        assert_eq!(gate.handle_wrong_token(S * 8, ip(2)), FIRST_FAILURE_DELAY);
        let line = gate.poll_log(S * 8).expect("the first report at once");
        assert!(line.starts_with("9 WebSockets refused"), "{line}");
        assert!(line.contains("8 from 10.0.0.1, 1 from 10.0.0.2"), "{line}");
        // Fifty more guesses: one line a minute, not fifty.
        for i in 0..50 {
            gate.handle_wrong_token(S * 9 + Duration::from_millis(20 * i), ip(1));
        }
        assert_eq!(gate.poll_log(S * 10), None);
        let line = gate.poll_log(S * 70).expect("a minute on");
        assert!(line.starts_with("50 WebSockets refused"), "{line}");
        // Forgotten after a quiet minute: no delay beyond the first.
        assert_eq!(gate.handle_wrong_token(S * 200, ip(1)), FIRST_FAILURE_DELAY);
    }
}
