//! Who may connect and what they may do, without I/O: users with a role and a token, a page's
//! WebSocket admitted only with a user's token and from the page's own origin.

use std::fmt;

use serde::Deserialize;

use crate::http::Head;

/// What a user may do. Each role may do what the ones before it may.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Role {
    /// See the state and the stops.
    View,
    /// And latch and release its own stops (the E-STOP).
    Stop,
    /// And take teleop control and drive.
    Drive,
}

impl Role {
    /// Every role, in order.
    pub const ALL: [Role; 3] = [Role::View, Role::Stop, Role::Drive];

    /// Its name in the configuration and on the page.
    pub fn name(self) -> &'static str {
        match self {
            Role::View => "view",
            Role::Stop => "stop",
            Role::Drive => "drive",
        }
    }

    /// The role named `name`.
    pub fn parse(name: &str) -> Option<Role> {
        Role::ALL.into_iter().find(|role| role.name() == name)
    }
}

impl fmt::Display for Role {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A user of the page: the owner of its stops is `web:NAME`.
#[derive(Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct User {
    /// Its name: 1 to 24 bytes of `A-Z a-z 0-9 . _ -`.
    pub name: String,
    /// What it may do.
    pub role: Role,
    /// Its secret (at least 16 characters).
    pub token: String,
}

impl fmt::Debug for User {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // Never the token: users are logged.
        f.debug_struct("User")
            .field("name", &self.name)
            .field("role", &self.role)
            .finish_non_exhaustive()
    }
}

/// The prefix of a page user's client name: the owner of its stops, the holder of its lease.
pub const WEB_PREFIX: &str = "web:";

/// The longest user name (`web:` and it fit a client name).
pub const MAX_USER_NAME: usize = 24;

/// The shortest token accepted.
pub const MIN_TOKEN: usize = 16;

impl User {
    /// Its client name, `web:NAME`.
    pub fn client_name(&self) -> String {
        format!("{WEB_PREFIX}{}", self.name)
    }

    /// Checks the name and token.
    pub fn check(&self) -> Result<(), UsersError> {
        let name_ok = !self.name.is_empty()
            && self.name.len() <= MAX_USER_NAME
            && self
                .name
                .bytes()
                .all(|byte| byte.is_ascii_alphanumeric() || matches!(byte, b'.' | b'_' | b'-'));
        if !name_ok {
            return Err(UsersError::Name(self.name.clone()));
        }
        if self.token.chars().count() < MIN_TOKEN || self.token.chars().any(char::is_whitespace) {
            return Err(UsersError::Token(self.name.clone()));
        }
        Ok(())
    }
}

/// Why the users cannot be served.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum UsersError {
    /// None given.
    #[error("no users: give at least one")]
    None,
    /// A name that is not one.
    #[error("user name {0:?}: 1 to {MAX_USER_NAME} of A-Z a-z 0-9 . _ -")]
    Name(String),
    /// A token too short, or with spaces.
    #[error("user {0}: its token needs at least {MIN_TOKEN} characters and no spaces")]
    Token(String),
    /// A name given twice.
    #[error("user {0} is given twice")]
    Twice(String),
    /// Two users with one token: the token would not tell them apart.
    #[error("users {0} and {1} have the same token")]
    SameToken(String, String),
}

/// The users, checked: names and tokens distinct.
#[derive(Debug, Clone)]
pub struct Users(Vec<User>);

impl Users {
    /// Checks `users`: at least one, each valid, no name or token twice.
    pub fn new(users: Vec<User>) -> Result<Users, UsersError> {
        if users.is_empty() {
            return Err(UsersError::None);
        }
        for (at, user) in users.iter().enumerate() {
            user.check()?;
            for other in &users[..at] {
                if other.name == user.name {
                    return Err(UsersError::Twice(user.name.clone()));
                }
                if other.token == user.token {
                    return Err(UsersError::SameToken(other.name.clone(), user.name.clone()));
                }
            }
        }
        Ok(Users(users))
    }

    /// The users.
    pub fn all(&self) -> &[User] {
        &self.0
    }

    /// The user whose token is `token`, comparing every token in full (no early exit that
    /// would tell how much of a guess was right).
    pub fn by_token(&self, token: &str) -> Option<&User> {
        let mut found = None;
        for user in &self.0 {
            if same_secret(user.token.as_bytes(), token.as_bytes()) {
                found = Some(user);
            }
        }
        found
    }
}

/// Compares two secrets in time that depends on their lengths only.
fn same_secret(a: &[u8], b: &[u8]) -> bool {
    let mut differ = a.len() ^ b.len();
    for (at, byte) in a.iter().enumerate() {
        differ |= usize::from(byte ^ b.get(at).copied().unwrap_or(!byte));
    }
    differ == 0
}

/// A new random token: 24 characters of URL-safe base 64 (144 bits).
pub fn new_token() -> Result<String, getrandom::Error> {
    const ALPHABET: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_";
    let mut bytes = [0u8; 24];
    getrandom::fill(&mut bytes)?;
    Ok(bytes
        .iter()
        .map(|byte| char::from(ALPHABET[usize::from(byte & 63)]))
        .collect())
}

/// Why a WebSocket is refused: the HTTP status and the reason (sent to the browser and logged).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Refusal {
    /// 401 (no or wrong token) or 403 (another origin).
    pub status: u16,
    /// What went wrong.
    pub reason: String,
}

/// Admits a page's WebSocket request: its `Origin` must be the page's own (the `Host` it asked,
/// on `scheme`), its `token` a user's. Returns that user.
pub fn admit<'a>(head: &Head, users: &'a Users, scheme: &str) -> Result<&'a User, Refusal> {
    let host = head.header("host").unwrap_or("");
    let own = format!("{scheme}://{host}");
    match head.header("origin") {
        Some(origin) if !host.is_empty() && origin.eq_ignore_ascii_case(&own) => {}
        Some(origin) => {
            return Err(Refusal {
                status: 403,
                reason: format!(
                    "a WebSocket from origin {origin} is refused: only {own}'s own page may connect"
                ),
            });
        }
        None => {
            return Err(Refusal {
                status: 403,
                reason: "a WebSocket without an Origin is refused: open the page in a browser"
                    .into(),
            });
        }
    }
    let token = head.query.get("token").map(String::as_str).unwrap_or("");
    if token.is_empty() {
        return Err(Refusal {
            status: 401,
            reason: "no token: open the link scout web printed (it ends in #token=...)".into(),
        });
    }
    users.by_token(token).ok_or_else(|| Refusal {
        status: 401,
        reason: "wrong token: ask for the link scout web printed, or the token in its config"
            .into(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn users() -> Users {
        Users::new(vec![
            User {
                name: "alice".into(),
                role: Role::Drive,
                token: "alice-token-0123456789".into(),
            },
            User {
                name: "bob".into(),
                role: Role::View,
                token: "bob-token-0123456789ab".into(),
            },
        ])
        .expect("valid")
    }

    fn head(origin: Option<&str>, token: Option<&str>) -> Head {
        let mut text = String::from("GET /ws");
        if let Some(token) = token {
            text.push_str(&format!("?token={token}"));
        }
        text.push_str(
            " HTTP/1.1\r\nHost: 127.0.0.1:8090\r\nUpgrade: websocket\r\nSec-WebSocket-Key: x\r\n",
        );
        if let Some(origin) = origin {
            text.push_str(&format!("Origin: {origin}\r\n"));
        }
        text.push_str("\r\n");
        Head::parse(text.as_bytes()).expect("head").0
    }

    #[test]
    fn the_right_token_from_the_pages_origin_is_its_user() {
        let users = users();
        let user = admit(
            &head(
                Some("http://127.0.0.1:8090"),
                Some("bob-token-0123456789ab"),
            ),
            &users,
            "http",
        )
        .expect("admitted");
        assert_eq!(user.client_name(), "web:bob");
        assert_eq!(user.role, Role::View);
    }

    #[test]
    fn no_token_a_wrong_one_another_origin_or_scheme_are_refused() {
        let users = users();
        let refused =
            |head: Head, scheme: &str| admit(&head, &users, scheme).expect_err("refused").status;
        assert_eq!(
            refused(head(Some("http://127.0.0.1:8090"), None), "http"),
            401
        );
        assert_eq!(
            refused(
                head(Some("http://127.0.0.1:8090"), Some("alice-token-012345678")),
                "http"
            ),
            401
        );
        assert_eq!(
            refused(
                head(
                    Some("http://127.0.0.1:8090"),
                    Some("alice-token-01234567890")
                ),
                "http"
            ),
            401
        );
        assert_eq!(
            refused(
                head(Some("http://evil.example"), Some("alice-token-0123456789")),
                "http"
            ),
            403
        );
        assert_eq!(
            refused(head(None, Some("alice-token-0123456789")), "http"),
            403
        );
        assert_eq!(
            refused(
                head(
                    Some("http://127.0.0.1:8090"),
                    Some("alice-token-0123456789")
                ),
                "https"
            ),
            403
        );
    }

    #[test]
    fn bad_users_are_named() {
        let user = |name: &str, token: &str| User {
            name: name.into(),
            role: Role::Stop,
            token: token.into(),
        };
        assert!(Users::new(vec![]).is_err());
        let refused = |users| Users::new(users).map(|_| ()).unwrap_err().to_string();
        assert!(refused(vec![user("a b", "0123456789abcdef")]).contains("user name"));
        assert!(refused(vec![user("a", "short")]).contains("16"));
        assert!(
            refused(vec![
                user("a", "0123456789abcdef"),
                user("a", "0123456789abcdeg")
            ])
            .contains("twice")
        );
        assert!(
            refused(vec![
                user("a", "0123456789abcdef"),
                user("b", "0123456789abcdef")
            ])
            .contains("same token")
        );
        assert!(
            !format!("{:?}", user("a", "0123456789abcdef")).contains("0123"),
            "no token in logs"
        );
    }

    #[test]
    fn secrets_compare_in_full() {
        assert!(same_secret(b"abc", b"abc"));
        assert!(!same_secret(b"abc", b"abd"));
        assert!(!same_secret(b"abc", b"ab"));
        assert!(!same_secret(b"", b"a"));
        assert!(same_secret(b"", b""));
        let token = new_token().expect("random");
        assert_eq!(token.len(), 24);
        assert_ne!(token, new_token().expect("random"));
    }
}
