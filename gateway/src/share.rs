//! Request budgets, sans-IO: a token bucket per sender ([`TokenBucket`], the arbiter's per-client
//! limit) and one per user of the stop endpoint ([`UserShares`]), so that one user's flood is
//! refused at its share while everyone else's requests are served.

use std::collections::HashMap;
use std::time::Duration;

/// Requests a sender may still send now: `burst` at most, refilled at `rate` per second.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TokenBucket {
    tokens: f64,
    at: Duration,
}

impl TokenBucket {
    /// A full bucket at `now`.
    pub fn full(burst: f64, now: Duration) -> Self {
        Self {
            tokens: burst,
            at: now,
        }
    }

    /// Takes one request at `now`; `false` when the budget is spent.
    pub fn take(&mut self, now: Duration, rate: f64, burst: f64) -> bool {
        let refill = now.saturating_sub(self.at).as_secs_f64() * rate;
        self.tokens = (self.tokens + refill).min(burst);
        self.at = self.at.max(now);
        if self.tokens < 1.0 {
            return false;
        }
        self.tokens -= 1.0;
        true
    }
}

/// Users whose shares are kept at once; past this the oldest are forgotten (a forgotten user
/// starts again with a full bucket: at worst one more burst).
pub const MAX_USERS: usize = 256;

/// Each user's share of the stop endpoint's work, by the user id the kernel vouches for.
#[derive(Debug, Clone)]
pub struct UserShares {
    rate: f64,
    burst: f64,
    buckets: HashMap<u32, TokenBucket>,
}

impl UserShares {
    /// Shares of `rate` requests a second and `burst` at once, per user.
    pub fn new(rate: f64, burst: u32) -> Self {
        Self {
            rate,
            burst: f64::from(burst),
            buckets: HashMap::new(),
        }
    }

    /// The share's rate, per second.
    pub fn rate(&self) -> f64 {
        self.rate
    }

    /// Takes one request of user `uid` at `now`; `false` when its share is spent.
    pub fn admit(&mut self, now: Duration, uid: u32) -> bool {
        if !self.buckets.contains_key(&uid) && self.buckets.len() >= MAX_USERS {
            let oldest = self
                .buckets
                .iter()
                .min_by_key(|(_, bucket)| bucket.at)
                .map(|(uid, _)| *uid);
            if let Some(oldest) = oldest {
                self.buckets.remove(&oldest);
            }
        }
        let (rate, burst) = (self.rate, self.burst);
        self.buckets
            .entry(uid)
            .or_insert_with(|| TokenBucket::full(burst, now))
            .take(now, rate, burst)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn ms(ms: u64) -> Duration {
        Duration::from_millis(ms)
    }

    #[test]
    fn a_bucket_gives_its_burst_then_its_rate() {
        let mut bucket = TokenBucket::full(3.0, ms(1000));
        let taken = (0..10)
            .filter(|_| bucket.take(ms(1000), 100.0, 3.0))
            .count();
        assert_eq!(taken, 3);
        // 100 a second: one more after 10 ms, none before.
        assert!(!bucket.take(ms(1005), 100.0, 3.0));
        assert!(bucket.take(ms(1010), 100.0, 3.0));
        // Time running backwards refills nothing.
        assert!(!bucket.take(ms(900), 100.0, 3.0));
    }

    #[test]
    fn one_users_flood_spends_its_own_share_only() {
        let mut shares = UserShares::new(500.0, 50);
        let now = ms(5000);
        let flood = (0..10_000).filter(|_| shares.admit(now, 1001)).count();
        assert_eq!(flood, 50);
        assert!(shares.admit(now, 1000), "another user is served");
        assert!(shares.admit(now + ms(2), 1001), "the flood's share refills");
    }

    #[test]
    fn users_past_the_limit_forget_the_oldest() {
        let mut shares = UserShares::new(1.0, 1);
        for uid in 0..MAX_USERS as u32 {
            assert!(shares.admit(ms(u64::from(uid)), uid));
        }
        // User 0 is spent; a new user pushes out the oldest (user 0), which starts full again.
        assert!(!shares.admit(ms(300), 1));
        assert!(shares.admit(ms(300), 100_000));
        assert_eq!(shares.buckets.len(), MAX_USERS);
        assert!(shares.admit(ms(301), 0));
    }

    proptest! {
        /// Over any window, a user gets at most its burst plus the rate times the window.
        #[test]
        fn a_share_never_gives_more_than_burst_plus_rate(
            gaps in proptest::collection::vec(0u64..20, 1..400),
            rate in 1.0f64..1000.0,
            burst in 1u32..100,
        ) {
            let mut shares = UserShares::new(rate, burst);
            let start = ms(10_000);
            let mut now = start;
            let mut admitted = 0u64;
            for gap in gaps {
                now += ms(gap);
                admitted += u64::from(shares.admit(now, 7));
            }
            let window = (now - start).as_secs_f64();
            prop_assert!(admitted as f64 <= f64::from(burst) + rate * window + 1e-9);
        }
    }
}
