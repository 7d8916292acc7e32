//! The remote-command rules without I/O: who a command is from (its key), whether the gateway
//! grants it, its order and age on the peer's own clock, and the lease it holds. Time and
//! commands in ([`Rules::handle_command`]), what to send to the arbiter out; the arbiter's answer
//! back in ([`Rules::handle_answer`]). The bridge's thread is the driver that touches zenoh,
//! iceoryx2 and the clock.

use std::collections::VecDeque;
use std::time::Duration;

use scout_interface::control::{Accepted, Class, Request};
use scout_interface::remote::{
    self, CommandError, LINK_AGES, LinkQuality, MAX_COMMAND_BYTES, Permission, RemoteCommand,
    RemoteCommands, RemoteKind, SenderTiming, TimingError, peer_client_name,
};
use scout_interface::services::RequestError;

/// Remote peers kept at once; the least recently used is forgotten past this.
pub const MAX_REMOTE_PEERS: usize = 16;

/// The longest a remote drive command may live: the chassis' own timeout.
pub const MAX_REMOTE_LIFE: Duration = Duration::from_millis(500);

/// A peer silent this long has its timing (drive numbers, clock offset) and any lease the
/// rules still knew forgotten: no command is held up that long, no lease outlives its commands
/// that long, and its next session may use another clock.
pub const FORGET_TIMING_AFTER: Duration = Duration::from_secs(60);

/// What the rules keep of remote peers.
#[derive(Debug)]
pub struct Rules {
    commands: RemoteCommands,
    peers: Vec<Peer>,
    used: u64,
}

/// What the rules keep of one remote peer.
#[derive(Debug)]
struct Peer {
    /// Its client name (`remote:...`).
    name: String,
    /// The lease it took and its class.
    lease: Option<(u64, Class)>,
    /// Its drives' order and its clock as this host sees them: how late its commands arrive.
    timing: SenderTiming,
    used: u64,
    /// When its last command arrived.
    seen: Duration,
    /// How its drives fared (`peer`, `age_*` and `last_seen_ms` are filled in when reported).
    link: LinkQuality,
    /// The ages of its last [`LINK_AGES`] drives, ms.
    ages: VecDeque<u64>,
}

/// A command the rules let through: the request and where it goes.
#[derive(Debug, Clone, PartialEq)]
pub struct Send {
    /// The peer's client name (`remote:...`): the owner of what the request does.
    pub peer: String,
    /// The arbiter request.
    pub request: Request,
    /// Which port carries it.
    pub via: Via,
    /// A peer forgotten to make room for this one: the driver closes its port.
    pub evicted: Option<String>,
}

/// The port a request goes through.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Via {
    /// The bridge's stop port, naming the peer (releases: they need no control).
    Safety,
    /// The peer's own control port, stamped `sent` on this host's clock (when the peer sent
    /// it, as far as its age tells).
    Control {
        /// The send time the arbiter ages the request by.
        sent: Duration,
    },
}

impl Rules {
    /// Rules granting what `commands` allows (`commands.enabled` is the driver's to check: a
    /// disabled gateway never asks the rules).
    pub fn new(commands: RemoteCommands) -> Self {
        Self {
            commands,
            peers: Vec::new(),
            used: 0,
        }
    }

    /// A command that arrived at `now` (this host's clock) on `key` with `payload`: the request
    /// to send, or why it is refused. Nothing is kept for a peer before its command passed the
    /// permission check.
    pub fn handle_command(
        &mut self,
        now: Duration,
        key: &str,
        payload: Option<&[u8]>,
    ) -> Result<Send, CommandError> {
        let (kind, peer) = remote::parse_command_key(key)?;
        let name = peer_client_name(peer);
        let payload = payload.ok_or(CommandError::NoPayload)?;
        if payload.len() > MAX_COMMAND_BYTES {
            return Err(CommandError::TooLarge {
                size: payload.len(),
                max: MAX_COMMAND_BYTES,
            });
        }
        let command: RemoteCommand = serde_json::from_slice(payload)
            .map_err(|error| CommandError::Json(error.to_string()))?;
        let lease = (self.peers.iter())
            .find(|known| known.name == name)
            .and_then(|known| known.lease);
        let (permission, request) = match command.request(kind, lease) {
            Ok(asked) => asked,
            Err(error) => {
                // A drive from a peer kept (it was granted before) is counted on its link.
                if kind == RemoteKind::Drive
                    && let Some(known) = self.peers.iter_mut().find(|known| known.name == name)
                {
                    known.link.received += 1;
                    known.link.no_control += u64::from(error.lost_control());
                }
                return Err(error);
            }
        };
        // The permission before anything is kept for this peer.
        self.allowed(permission)?;
        if let Request::Release { .. } = request {
            return Ok(Send {
                peer: name,
                request,
                via: Via::Safety,
                evicted: None,
            });
        }
        let (peer, evicted) = self.peer(&name, now)?;
        let sent = match kind {
            RemoteKind::TakeControl | RemoteKind::Drive => peer.on_time(now, kind, &command)?,
            RemoteKind::Relinquish
            | RemoteKind::Estop
            | RemoteKind::Release
            | RemoteKind::Resume
            | RemoteKind::Lights
            | RemoteKind::ClearFault => now,
        };
        Ok(Send {
            peer: name,
            request,
            via: Via::Control { sent },
            evicted,
        })
    }

    /// The arbiter's answer to `request`, sent for `peer`: a lease taken, given up or lost.
    pub fn handle_answer(
        &mut self,
        peer: &str,
        request: &Request,
        answer: &Result<Accepted, RequestError>,
    ) {
        let Some(peer) = self.peers.iter_mut().find(|known| known.name == peer) else {
            return;
        };
        let lost_control =
            matches!(answer, Err(RequestError::Rejected(rejected)) if rejected.lost_control());
        match (request, answer) {
            (Request::Drive { .. }, Ok(_)) => peer.link.accepted += 1,
            (Request::Drive { .. }, Err(_)) if lost_control => {
                peer.link.no_control += 1;
                peer.lease = None;
            }
            // A control session starts its drive numbers anew (a client's `seq` counts from 1
            // each time it runs); the offset stays, so drives held up from before still age.
            (Request::TakeControl { class }, Ok(accepted)) => {
                peer.lease = accepted.lease.map(|lease| (lease, *class));
                peer.timing.new_session();
            }
            // Given up on purpose: the next session may come from another clock (a reboot,
            // another machine under this name), and its take-control seeds the age check.
            (Request::Relinquish, Ok(_)) => {
                peer.lease = None;
                peer.timing = SenderTiming::default();
            }
            // Revoked or not held: the peer must take control again.
            _ if lost_control => peer.lease = None,
            _ => {}
        }
    }

    /// Whether the peer named `name` (a client name) holds control, as far as the answers
    /// told.
    pub fn holds(&self, name: &str) -> bool {
        self.peers
            .iter()
            .any(|peer| peer.name == name && peer.lease.is_some())
    }

    /// Whether the gateway grants `permission` to remote peers.
    pub fn allowed(&self, permission: Permission) -> Result<(), CommandError> {
        allowed(&self.commands, permission)
    }

    /// How each peer's drives fared, as of `now`: the least recently seen first.
    pub fn links(&self, now: Duration) -> Vec<LinkQuality> {
        let mut peers: Vec<&Peer> = self.peers.iter().collect();
        peers.sort_by_key(|peer| peer.used);
        peers.iter().map(|peer| peer.link_quality(now)).collect()
    }

    /// The peer named `name` (a client name), seen at `now` and kept from now on; past
    /// [`MAX_REMOTE_PEERS`] the least recently used that holds no control is forgotten (its
    /// name returned): peers that hold nothing never push out one that drives. With every
    /// kept peer holding control, a new one is refused.
    fn peer(
        &mut self,
        name: &str,
        now: Duration,
    ) -> Result<(&mut Peer, Option<String>), CommandError> {
        self.used += 1;
        let used = self.used;
        let mut evicted = None;
        let index = match self.peers.iter().position(|peer| peer.name == name) {
            Some(index) => index,
            None => {
                if self.peers.len() >= MAX_REMOTE_PEERS {
                    let idle = (0..self.peers.len())
                        .filter(|&i| self.peers[i].lease.is_none())
                        .min_by_key(|&i| self.peers[i].used)
                        .ok_or(CommandError::TooManyPeers {
                            max: MAX_REMOTE_PEERS,
                        })?;
                    evicted = Some(self.peers.swap_remove(idle).name);
                }
                self.peers.push(Peer {
                    name: name.to_owned(),
                    lease: None,
                    timing: SenderTiming::default(),
                    used,
                    seen: now,
                    link: LinkQuality::default(),
                    ages: VecDeque::new(),
                });
                self.peers.len() - 1
            }
        };
        let peer = &mut self.peers[index];
        // Silent for longer than anything zenoh holds up (its session lease is 10 s by
        // default): its timing is forgotten, as after a relinquish. A lease it held is gone
        // too (the arbiter ends one within 500 ms of its last command), though no answer said
        // so: a client that died without giving control up.
        if now.saturating_sub(peer.seen) > FORGET_TIMING_AFTER {
            peer.lease = None;
            peer.timing = SenderTiming::default();
        }
        peer.used = used;
        peer.seen = now;
        Ok((peer, evicted))
    }
}

/// Whether `commands` grant `permission` to remote peers (the e-stop lane asks too).
pub fn allowed(commands: &RemoteCommands, permission: Permission) -> Result<(), CommandError> {
    if commands.allowed.contains(&permission) {
        return Ok(());
    }
    Err(CommandError::NotAllowed {
        permission,
        allowed: commands.allowed_names(),
    })
}

impl Peer {
    /// Checks a take-control's or drive command's age (and a drive's order) at `now`; returns
    /// when it was sent, on this host's clock ([`SenderTiming::check`]: a drive's `seq` rises
    /// by a plausible step, a stamp is neither from the future nor older than its life,
    /// measured against the fastest delivery seen from this peer, so no common clock is
    /// needed). A take-control carries `sent_ms` too: it seeds that measure, so the first
    /// drive is aged like every later one. A refused command teaches nothing.
    fn on_time(
        &mut self,
        now: Duration,
        kind: RemoteKind,
        command: &RemoteCommand,
    ) -> Result<Duration, CommandError> {
        let drive = kind == RemoteKind::Drive;
        let (Some(sent_ms), Some(seq)) = (
            command.sent_ms,
            if drive {
                command.seq.map(Some)
            } else {
                Some(None)
            },
        ) else {
            return Err(CommandError::Missing(match kind {
                RemoteKind::Drive => {
                    "drive needs `seq` (rising) and `sent_ms` (the sender's clock, ms)"
                }
                _ => {
                    "take-control needs `sent_ms` (the sender's clock, ms): it seeds the age check of the drives that follow"
                }
            }));
        };
        let life = command.ttl_ms.map_or(MAX_REMOTE_LIFE, |ms| {
            Duration::from_millis(u64::from(ms)).min(MAX_REMOTE_LIFE)
        });
        let checked = self.timing.check(now, seq, sent_ms, life);
        if drive {
            self.link.received += 1;
            match &checked {
                Ok(checked) => {
                    if let (Some(seq), Some(last)) = (seq, self.timing.last_seq()) {
                        self.link.lost = self.link.lost.saturating_add(seq - last - 1);
                    }
                    self.record_age(now.saturating_sub(checked.sent));
                }
                Err(TimingError::OutOfOrder { .. } | TimingError::Leap { .. }) => {
                    self.link.reordered += 1;
                }
                Err(TimingError::Late { late, .. }) => {
                    self.link.late += 1;
                    self.record_age(*late);
                }
                Err(TimingError::Ahead { .. }) => {}
            }
        }
        let checked = checked?;
        self.timing.accept(checked);
        Ok(checked.sent)
    }

    /// Keeps a drive's age, to the nearest ms, among the last [`LINK_AGES`].
    fn record_age(&mut self, late: Duration) {
        if self.ages.len() == LINK_AGES {
            self.ages.pop_front();
        }
        self.ages
            .push_back(late.saturating_add(Duration::from_micros(500)).as_millis() as u64);
    }

    /// Its link quality as of `now`.
    fn link_quality(&self, now: Duration) -> LinkQuality {
        let mut ages: Vec<u64> = self.ages.iter().copied().collect();
        ages.sort_unstable();
        // The nearest-rank percentile.
        let percentile =
            |p: usize| (!ages.is_empty()).then(|| ages[(ages.len() * p).div_ceil(100).max(1) - 1]);
        LinkQuality {
            peer: self.name.clone(),
            age_p50_ms: percentile(50),
            age_p99_ms: percentile(99),
            last_seen_ms: now.saturating_sub(self.seen).as_millis() as u64,
            ..self.link.clone()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use scout_interface::control::{Rejected, RejectionKind};

    const MS: Duration = Duration::from_millis(1);

    fn rules(allowed: &[Permission]) -> Rules {
        Rules::new(RemoteCommands {
            enabled: true,
            allowed: allowed.to_vec(),
        })
    }

    fn teleop() -> Rules {
        rules(&[Permission::Estop, Permission::Teleop, Permission::Release])
    }

    fn key(kind: &str, peer: &str) -> String {
        format!("scout/r/cmd/{kind}/{peer}")
    }

    fn take(rules: &mut Rules, now: Duration, peer: &str, sent_ms: u64) -> Send {
        let payload = format!(r#"{{"class":"teleop","sent_ms":{sent_ms}}}"#);
        let send =
            (rules.handle_command(now, &key("take-control", peer), Some(payload.as_bytes())))
                .expect("take-control passes");
        rules.handle_answer(
            &send.peer,
            &send.request,
            &Ok(Accepted {
                lease: Some(7),
                ..Accepted::default()
            }),
        );
        send
    }

    fn drive(
        rules: &mut Rules,
        now: Duration,
        peer: &str,
        seq: u64,
        sent_ms: u64,
    ) -> Result<Send, CommandError> {
        let payload = format!(r#"{{"seq":{seq},"sent_ms":{sent_ms},"linear":0.5,"angular":0.0}}"#);
        rules.handle_command(now, &key("drive", peer), Some(payload.as_bytes()))
    }

    #[test]
    fn a_drive_needs_a_lease_and_goes_on_the_peer_s_control_port() {
        let mut rules = teleop();
        let refused = drive(&mut rules, 1000 * MS, "op", 1, 50).expect_err("no lease yet");
        assert!(matches!(refused, CommandError::NoControl(_)), "{refused}");
        take(&mut rules, 1000 * MS, "op", 50);
        let send = drive(&mut rules, 1020 * MS, "op", 1, 70).expect("leased");
        assert_eq!(send.peer, "remote:op");
        assert_eq!(send.via, Via::Control { sent: 1020 * MS });
        assert!(matches!(send.request, Request::Drive { lease: 7, .. }));
    }

    #[test]
    fn drives_in_order_only() {
        let mut rules = teleop();
        take(&mut rules, 1000 * MS, "op", 0);
        drive(&mut rules, 1010 * MS, "op", 5, 10).expect("first");
        for seq in [5, 4, 0] {
            let refused = drive(&mut rules, 1020 * MS, "op", seq, 20).expect_err("not newer");
            assert!(matches!(
                refused,
                CommandError::Timing(TimingError::OutOfOrder { last: 5, .. })
            ));
        }
        drive(&mut rules, 1030 * MS, "op", 9, 30).expect("a gap is fine");
    }

    #[test]
    fn a_drive_held_up_past_its_life_is_refused_and_ages_by_the_fastest_delivery() {
        let mut rules = teleop();
        // The peer's clock is 10 s behind; its fastest delivery so far took 20 ms.
        take(&mut rules, 10_020 * MS, "op", 0);
        let on_time = drive(&mut rules, 10_120 * MS, "op", 1, 100).expect("as fast");
        assert_eq!(on_time.via, Via::Control { sent: 10_120 * MS });
        // 300 ms slower than the fastest: sent 300 ms before it arrived, as far as we can tell.
        let slow = drive(&mut rules, 10_520 * MS, "op", 2, 200).expect("within 500 ms");
        // (80 µs later: in the 400 ms since, the offset may have risen 200 ppm.)
        let sent = Duration::from_micros(10_220_080);
        assert_eq!(slow.via, Via::Control { sent });
        let late = drive(&mut rules, 11_121 * MS, "op", 3, 300).expect_err("301 ms too late");
        // 801 ms, less the 0.2 ms the offset may have risen, in whole ms.
        assert!(
            matches!(
                late,
                CommandError::Timing(TimingError::Late { late, life })
                    if late.as_millis() == 800 && life == MAX_REMOTE_LIFE
            ),
            "{late}"
        );
        // A shorter ttl is a shorter life.
        let payload = br#"{"seq":4,"sent_ms":400,"ttl_ms":100,"linear":0,"angular":0}"#;
        let short = rules.handle_command(10_621 * MS, &key("drive", "op"), Some(payload));
        assert!(matches!(
            short,
            Err(CommandError::Timing(TimingError::Late { life, .. })) if life == 100 * MS
        ));
    }

    #[test]
    fn a_take_control_held_up_carries_when_it_was_sent() {
        // The arbiter refuses a take-control sent before a release or a lapse it arrives
        // after: it needs the send time, as far as the fastest delivery tells.
        let mut rules = teleop();
        take(&mut rules, 10_020 * MS, "op", 0);
        drive(&mut rules, 10_120 * MS, "op", 1, 100).expect("as fast");
        let payload = br#"{"class":"teleop","sent_ms":300}"#;
        let held_up =
            (rules.handle_command(10_720 * MS, &key("take-control", "op"), Some(payload)))
                .expect("within its life");
        // Sent at 10 320 ms on this host's clock (80 µs later: the offset's allowed drift).
        let sent = Duration::from_micros(10_320_120);
        assert_eq!(held_up.via, Via::Control { sent });
        assert!(matches!(held_up.request, Request::TakeControl { .. }));
    }

    #[test]
    fn a_lost_lease_must_be_taken_again() {
        let mut rules = teleop();
        take(&mut rules, 1000 * MS, "op", 0);
        let send = drive(&mut rules, 1010 * MS, "op", 1, 10).expect("leased");
        rules.handle_answer(
            &send.peer,
            &send.request,
            &Err(RequestError::Rejected(Rejected {
                kind: Some(RejectionKind::Revoked),
                reason: "revoked".into(),
            })),
        );
        let refused = drive(&mut rules, 1020 * MS, "op", 2, 20).expect_err("lease gone");
        assert!(matches!(refused, CommandError::NoControl(_)));
    }

    #[test]
    fn permissions_come_first_and_keep_nothing() {
        let mut rules = rules(&[Permission::Estop]);
        for peer in 0..100 {
            let peer = format!("p{peer}");
            let refused = rules
                .handle_command(
                    MS,
                    &key("take-control", &peer),
                    Some(br#"{"class":"teleop","sent_ms":0}"#),
                )
                .expect_err("teleop not granted");
            assert!(matches!(refused, CommandError::NotAllowed { .. }));
        }
        assert!(rules.peers.is_empty(), "a refused peer is not kept");
        let stop = rules
            .handle_command(MS, &key("estop", "p1"), Some(b"{}"))
            .expect("estop granted");
        assert_eq!(stop.via, Via::Control { sent: MS });
    }

    #[test]
    fn releases_go_through_the_safety_port_naming_the_peer() {
        let mut rules = teleop();
        let send = (rules.handle_command(MS, &key("release", "op"), Some(br#"{"through":3}"#)))
            .expect("granted");
        assert_eq!(send.via, Via::Safety);
        assert_eq!(send.peer, "remote:op");
    }

    #[test]
    fn the_least_recently_used_peer_is_forgotten_and_named() {
        let mut rules = teleop();
        for peer in 0..MAX_REMOTE_PEERS {
            let send = rules
                .handle_command(MS, &key("estop", &format!("p{peer}")), Some(b"{}"))
                .expect("estop");
            assert_eq!(send.evicted, None);
        }
        // p0 is used again: p1 is the least recently used.
        rules
            .handle_command(MS, &key("estop", "p0"), Some(b"{}"))
            .expect("estop");
        let send = (rules.handle_command(MS, &key("estop", "new"), Some(b"{}"))).expect("estop");
        assert_eq!(send.evicted.as_deref(), Some("remote:p1"));
        assert_eq!(rules.peers.len(), MAX_REMOTE_PEERS);
    }

    #[test]
    fn bad_input_says_why() {
        let mut rules = teleop();
        let cases: [(&str, Option<&[u8]>); 4] = [
            ("scout/r/cmd/drive", Some(b"{}")),
            ("scout/r/cmd/drive/op", None),
            ("scout/r/cmd/drive/op", Some(b"not json")),
            ("scout/r/cmd/fly/op", Some(b"{}")),
        ];
        for (key, payload) in cases {
            assert!(rules.handle_command(MS, key, payload).is_err(), "{key}");
        }
        let big = vec![b' '; MAX_COMMAND_BYTES + 1];
        assert!(matches!(
            rules.handle_command(MS, &key("estop", "op"), Some(&big)),
            Err(CommandError::TooLarge { .. })
        ));
    }

    #[test]
    fn link_quality_counts_what_the_peer_s_drives_met() {
        let mut rules = teleop();
        take(&mut rules, 1000 * MS, "op", 0);
        let accept = |rules: &mut Rules, send: Send| {
            let answer = Ok(Accepted::default());
            rules.handle_answer(&send.peer, &send.request, &answer);
        };
        // Fastest delivery 1000 ms (the offset); then 10, 30, 600 (late) ms slower.
        let first = drive(&mut rules, 1000 * MS, "op", 1, 0).expect("on time");
        accept(&mut rules, first);
        let second = drive(&mut rules, 1030 * MS, "op", 2, 20).expect("on time");
        accept(&mut rules, second);
        // Seqs 3 and 4 never came; 5 is repeated.
        drive(&mut rules, 1070 * MS, "op", 5, 40).expect("a gap is let through");
        drive(&mut rules, 1080 * MS, "op", 5, 50).expect_err("repeated");
        drive(&mut rules, 1700 * MS, "op", 6, 100).expect_err("600 ms late");
        // Its control ends: the next drive is refused, and counted.
        rules
            .handle_command(1750 * MS, &key("relinquish", "op"), Some(b"{}"))
            .expect("granted");
        rules.handle_answer("remote:op", &Request::Relinquish, &Ok(Accepted::default()));
        drive(&mut rules, 1750 * MS, "op", 7, 150).expect_err("no control");
        let links = rules.links(1800 * MS);
        assert_eq!(
            links,
            [LinkQuality {
                peer: "remote:op".into(),
                received: 6,
                accepted: 2,
                late: 1,
                reordered: 1,
                no_control: 1,
                lost: 2,
                age_p50_ms: Some(10),
                age_p99_ms: Some(600),
                last_seen_ms: 50,
            }]
        );
        // Only the last LINK_AGES count; a jump to the last seq counts as lost, no overflow.
        take(&mut rules, 2000 * MS, "op", 1000);
        for seq in 0..LINK_AGES as u64 {
            let now = Duration::from_millis(2000 + seq);
            drive(&mut rules, now, "op", 10 + seq, 1000 + seq).expect("on time");
        }
        // The largest number there is: a leap no sender counts to, refused and not counted.
        drive(&mut rules, 3000 * MS, "op", u64::MAX, 2000).expect_err("a leap");
        drive(&mut rules, 3000 * MS, "op", 700, 2000).expect("a gap");
        let link = &rules.links(3000 * MS)[0];
        assert_eq!((link.age_p50_ms, link.age_p99_ms), (Some(0), Some(0)));
        // 3 and 4, then (the take-control started the numbers anew) everything past 265.
        assert_eq!(link.lost, 2 + (700 - 265 - 1));
    }

    #[test]
    fn a_slow_clock_drives_for_hours_and_a_link_that_holds_drives_up_is_still_seen() {
        let mut rules = teleop();
        // The peer's clock runs 100 ppm slow: 360 ms behind after an hour. Drives every 100 ms
        // for two hours, each delivered in 5 ms.
        take(&mut rules, 5 * MS, "op", 0);
        let peer_ms = |t_ms: u64| t_ms - t_ms / 10_000;
        for seq in 1..=72_000u64 {
            let sent = seq * 100;
            drive(
                &mut rules,
                Duration::from_millis(sent + 5),
                "op",
                seq,
                peer_ms(sent),
            )
            .unwrap_or_else(|error| panic!("drive {seq} at {sent} ms: {error}"));
        }
        let link = &rules.links(7_200_005 * MS)[0];
        // (The peer's clock here falls behind 1 ms at a time, which takes 5 s to absorb.)
        assert!(link.age_p99_ms <= Some(1), "{link:?}");
        // Now the link holds every drive up 520 ms more (their life is 500 ms): refused for a
        // minute on end (the offset rises 12 ms in it).
        for seq in 72_001..=72_600u64 {
            let sent = seq * 100;
            let now = Duration::from_millis(sent + 525);
            let refused = drive(&mut rules, now, "op", seq, peer_ms(sent)).expect_err("held up");
            assert!(
                matches!(refused, CommandError::Timing(TimingError::Late { .. })),
                "{refused}"
            );
        }
    }

    #[test]
    fn a_new_session_numbers_anew_and_a_new_clock_needs_a_relinquish_or_a_minute() {
        let mut rules = teleop();
        take(&mut rules, 1000 * MS, "op", 0);
        for seq in 1..=3u64 {
            let now = Duration::from_millis(1000 + seq * 10);
            drive(&mut rules, now, "op", seq, seq * 10).expect("on time");
        }
        // The same client run again: its numbers start at 1.
        take(&mut rules, 1100 * MS, "op", 100);
        drive(&mut rules, 1110 * MS, "op", 1, 110).expect("a new session's first drive");
        // A drive held up from before it is still aged by the old offset.
        drive(&mut rules, 1700 * MS, "op", 2, 120).expect_err("held up 580 ms");
        // Another clock, 3 s behind (a reboot): refused as held up while the peer is known...
        let behind = |rules: &mut Rules, now: Duration| {
            let payload = format!(r#"{{"class":"teleop","sent_ms":{}}}"#, 10);
            rules.handle_command(now, &key("take-control", "op"), Some(payload.as_bytes()))
        };
        behind(&mut rules, 3010 * MS).expect_err("3 s late by the old clock");
        // ... until the peer gives control up on purpose,
        rules
            .handle_command(3020 * MS, &key("relinquish", "op"), Some(b"{}"))
            .expect("granted");
        rules.handle_answer("remote:op", &Request::Relinquish, &Ok(Accepted::default()));
        behind(&mut rules, 3030 * MS).expect("the new clock seeds the age check");
        // or, without control, is silent for longer than anything is held up.
        let mut rules = teleop();
        take(&mut rules, 1000 * MS, "op", 0);
        rules.handle_answer(
            "remote:op",
            &Request::Relinquish,
            &Err(RequestError::Rejected(Rejected {
                kind: Some(RejectionKind::Revoked),
                reason: "revoked".into(),
            })),
        );
        behind(&mut rules, 30_000 * MS).expect_err("29 s late: maybe held up");
        let later = 30_000 * MS + FORGET_TIMING_AFTER + MS;
        behind(&mut rules, later).expect("forgotten after a silent minute");

        // A client that died holding control (no answer told the rules it ended): forgotten
        // after a silent minute all the same, lease included.
        let mut rules = teleop();
        let send = take(&mut rules, 1000 * MS, "op", 0);
        let granted = Ok(Accepted {
            lease: Some(7),
            ..Accepted::default()
        });
        rules.handle_answer(&send.peer, &send.request, &granted);
        behind(&mut rules, 30_000 * MS).expect_err("29 s late: maybe held up");
        let later = 30_000 * MS + FORGET_TIMING_AFTER + MS;
        behind(&mut rules, later).expect("forgotten after a silent minute");
        assert_eq!(rules.peers[0].lease, None);
    }

    #[test]
    fn a_forged_or_stray_drive_changes_nothing_and_the_real_driver_drives_on() {
        let mut rules = teleop();
        take(&mut rules, 1000 * MS, "op", 0);
        let real = |rules: &mut Rules, seq: u64| {
            let now = Duration::from_millis(1000 + seq * 20);
            drive(rules, now, "op", seq, seq * 20)
        };
        for seq in 1..=5 {
            real(&mut rules, seq).expect("the real driver");
        }
        // The largest number there is: a leap no sender counts to.
        let refused = drive(&mut rules, 1101 * MS, "op", u64::MAX, 101).expect_err("a leap");
        assert!(
            matches!(
                refused,
                CommandError::Timing(TimingError::Leap { last: 5, .. })
            ),
            "{refused}"
        );
        // A stamp an hour ahead: from the future, never learned.
        let refused = drive(&mut rules, 1102 * MS, "op", 6, 3_600_000).expect_err("ahead");
        assert!(
            matches!(refused, CommandError::Timing(TimingError::Ahead { .. })),
            "{refused}"
        );
        // Held up past its (short) life: refused, and its number not taken.
        let payload = br#"{"seq":7,"sent_ms":0,"ttl_ms":50,"linear":0.5,"angular":0}"#;
        let refused = rules
            .handle_command(1103 * MS, &key("drive", "op"), Some(payload))
            .expect_err("late");
        assert!(
            matches!(refused, CommandError::Timing(TimingError::Late { .. })),
            "{refused}"
        );
        for seq in 6..=20 {
            let send = real(&mut rules, seq).expect("the real driver drives on");
            assert_eq!(
                send.via,
                Via::Control {
                    sent: Duration::from_millis(1000 + seq * 20)
                },
                "aged as before"
            );
        }
        // A leap within what the time since allows is a lost stretch, not a forgery.
        drive(&mut rules, 2420 * MS, "op", 500, 1420).expect("a second of drives lost");
    }

    #[test]
    fn a_take_control_from_a_jumped_clock_starts_the_clock_anew() {
        let mut rules = teleop();
        take(&mut rules, 1000 * MS, "op", 0);
        drive(&mut rules, 1020 * MS, "op", 1, 20).expect("on time");
        // The sender rebooted with a clock 50 s ahead: its drives are from the future...
        drive(&mut rules, 1040 * MS, "op", 2, 50_040).expect_err("ahead");
        // ... until it takes control again, which learns the new clock.
        take(&mut rules, 1060 * MS, "op", 50_060);
        for seq in 1..=5u64 {
            let now = Duration::from_millis(1060 + seq * 20);
            let send = drive(&mut rules, now, "op", seq, 50_060 + seq * 20).expect("anew");
            assert_eq!(send.via, Via::Control { sent: now });
        }
    }

    #[test]
    fn a_take_control_held_up_on_its_way_does_not_lock_out_the_drives_after_it() {
        let mut rules = teleop();
        // The take-control arrives 600 ms after it was sent (a stall); its drives on time.
        take(&mut rules, 1600 * MS, "op", 1000);
        for seq in 1..=5u64 {
            let now = Duration::from_millis(1600 + seq * 20);
            let send = drive(&mut rules, now, "op", seq, 1600 + seq * 20)
                .expect("the session's first drive starts the clock anew");
            assert_eq!(send.via, Via::Control { sent: now });
        }
        // Later in the session a stamp from the future is refused as before.
        drive(&mut rules, 1720 * MS, "op", 6, 2500).expect_err("ahead");
    }

    #[test]
    fn peers_that_hold_nothing_never_push_out_one_that_drives() {
        let mut rules = teleop();
        take(&mut rules, 1000 * MS, "op", 0);
        // Take-controls under many names, none granted (the class is held).
        let held = Err(RequestError::Rejected(Rejected {
            kind: Some(RejectionKind::Held),
            reason: "held".into(),
        }));
        for (i, peer) in (0..100).map(|i| (i, format!("flood{i}"))) {
            let now = Duration::from_millis(1001 + i);
            let payload = format!(r#"{{"class":"teleop","sent_ms":{i}}}"#);
            let send = rules
                .handle_command(now, &key("take-control", &peer), Some(payload.as_bytes()))
                .expect("passes the rules");
            assert_ne!(
                send.evicted.as_deref(),
                Some("remote:op"),
                "the driver kept"
            );
            rules.handle_answer(&send.peer, &send.request, &held);
        }
        assert!(rules.holds("remote:op"));
        drive(&mut rules, 1120 * MS, "op", 1, 120).expect("drives on");
        // With every kept peer holding control, a new one is refused, not let in by eviction.
        let mut rules = teleop();
        for i in 0..MAX_REMOTE_PEERS {
            take(&mut rules, 1000 * MS, &format!("p{i}"), 0);
        }
        let refused = rules
            .handle_command(
                1001 * MS,
                &key("take-control", "late"),
                Some(br#"{"class":"teleop","sent_ms":1}"#),
            )
            .expect_err("no room");
        assert!(
            matches!(refused, CommandError::TooManyPeers { .. }),
            "{refused}"
        );
    }

    proptest! {
        /// Whatever arrives in whatever order: a drive let through is newer than every drive
        /// let through before it from that peer, never sent before it arrived nor more than its
        /// life before, and nothing panics.
        #[test]
        fn accepted_drives_rise_and_are_fresh(
            arrivals in proptest::collection::vec((0u64..5, 0u64..40, 0u64..2000, 0u64..3000), 1..60)
        ) {
            let mut rules = teleop();
            take(&mut rules, Duration::from_secs(5), "op", 0);
            let mut now = Duration::from_secs(5);
            let mut last_seq = None;
            for (step, seq, sent_ms, _) in arrivals {
                now += Duration::from_millis(step * 10);
                if let Ok(send) = drive(&mut rules, now, "op", seq, sent_ms) {
                    prop_assert!(last_seq.is_none_or(|last| seq > last));
                    last_seq = Some(seq);
                    let Via::Control { sent } = send.via else {
                        return Err(TestCaseError::fail("a drive goes on the control port"));
                    };
                    prop_assert!(sent <= now && now - sent <= MAX_REMOTE_LIFE);
                }
            }
        }
    }
}
