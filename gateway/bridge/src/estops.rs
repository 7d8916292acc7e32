//! Copies of one remote e-stop latch it once. A peer puts an e-stop and queries it, and asks
//! again when no answer comes, so over a lossy link any of them may arrive first and the rest
//! later. Each latching again would give the stop a new id (a re-latch is a new act that a
//! release decided before it must not clear), so a release decided on the first answer would
//! find a stop "latched after the status it was decided on" and be refused. An e-stop that
//! names itself (`seq` and `sent_ms`, on the peer's clock) is one act: its first arrival that
//! the gateway accepted latches, and a copy of it within [`COPY_WINDOW`] is answered as that
//! stop without latching again. A copy that comes after a release, from before it, does not
//! undo the release. Anything else (no number, another number, the first try refused) latches
//! as always: when in doubt, a stop latches.

use std::collections::VecDeque;
use std::time::Duration;

use scout_interface::control::Accepted;

/// E-stops remembered at once: the oldest is forgotten past this (its late copies then latch
/// again, which is the safe side).
pub const MAX_REMEMBERED: usize = 64;

/// A copy arriving this long after its e-stop latched latches again: a peer's copies go
/// within half a second, and a link that holds one back longer is no link to drive over.
pub const COPY_WINDOW: Duration = Duration::from_secs(10);

/// The e-stops latched lately, by peer and number.
#[derive(Debug, Default)]
pub struct EstopCopies {
    latched: VecDeque<Latched>,
}

/// One e-stop that latched.
#[derive(Debug)]
struct Latched {
    /// Its sender, as the transport named it.
    peer: String,
    /// Its `seq` and `sent_ms`.
    act: (u64, u64),
    /// When it latched, on the bridge's clock.
    at: Duration,
    /// The gateway's answer.
    accepted: Accepted,
}

impl EstopCopies {
    /// The answer to give an e-stop of `peer` named `act` arriving at `now`, if it is a copy of
    /// one that latched within [`COPY_WINDOW`]: it is not sent to the gateway again.
    pub fn copy_of(
        &mut self,
        now: Duration,
        peer: &str,
        act: Option<(u64, u64)>,
    ) -> Option<Accepted> {
        self.latched
            .retain(|latched| now.saturating_sub(latched.at) <= COPY_WINDOW);
        let act = act?;
        self.latched
            .iter()
            .find(|latched| latched.peer == peer && latched.act == act)
            .map(|latched| latched.accepted)
    }

    /// Remembers that the e-stop of `peer` named `act` latched at `now` with `accepted`.
    pub fn handle_latched(
        &mut self,
        now: Duration,
        peer: &str,
        act: Option<(u64, u64)>,
        accepted: &Accepted,
    ) {
        let Some(act) = act else {
            return;
        };
        if self.latched.len() >= MAX_REMEMBERED {
            self.latched.pop_front();
        }
        self.latched.push_back(Latched {
            peer: peer.to_owned(),
            act,
            at: now,
            accepted: *accepted,
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stop(id: u64) -> Accepted {
        Accepted {
            stop: Some(id),
            ..Accepted::default()
        }
    }

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn the_copies_of_one_e_stop_are_answered_as_the_stop_it_latched() {
        let mut copies = EstopCopies::default();
        let act = Some((7, 123_456));
        assert_eq!(copies.copy_of(MS, "remote:alice", act), None);
        copies.handle_latched(MS, "remote:alice", act, &stop(4));
        for at in [2, 150, 450] {
            assert_eq!(
                copies.copy_of(at * MS, "remote:alice", act),
                Some(stop(4)),
                "{at} ms"
            );
        }
    }

    #[test]
    fn another_e_stop_another_peer_or_an_unnamed_one_latches() {
        let mut copies = EstopCopies::default();
        copies.handle_latched(MS, "remote:alice", Some((7, 100)), &stop(4));
        // The same peer's next e-stop, one with the same number on another clock reading
        // (a restarted client), another peer's with the same numbers, and any without.
        assert_eq!(copies.copy_of(MS, "remote:alice", Some((8, 100))), None);
        assert_eq!(copies.copy_of(MS, "remote:alice", Some((7, 101))), None);
        assert_eq!(copies.copy_of(MS, "remote:bob", Some((7, 100))), None);
        assert_eq!(copies.copy_of(MS, "remote:alice", None), None);
        copies.handle_latched(MS, "remote:alice", None, &stop(5));
        assert_eq!(copies.copy_of(MS, "remote:alice", None), None);
    }

    #[test]
    fn a_copy_past_the_window_or_the_memory_latches_again() {
        let mut copies = EstopCopies::default();
        copies.handle_latched(Duration::ZERO, "remote:alice", Some((1, 1)), &stop(1));
        assert_eq!(
            copies.copy_of(COPY_WINDOW + MS, "remote:alice", Some((1, 1))),
            None
        );
        for n in 0..=MAX_REMEMBERED as u64 {
            copies.handle_latched(Duration::ZERO, "remote:alice", Some((n, 0)), &stop(n));
        }
        assert_eq!(copies.latched.len(), MAX_REMEMBERED);
        assert_eq!(copies.copy_of(MS, "remote:alice", Some((0, 0))), None);
        assert_eq!(
            copies.copy_of(MS, "remote:alice", Some((1, 0))),
            Some(stop(1))
        );
    }
}
