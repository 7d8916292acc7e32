//! The emulated adapter without I/O: FunctionFS's descriptor and string blobs, its ep0 events,
//! and the answers a candleLight gives to the gs_usb vendor requests.

use scout_protocol::gs_usb::{
    self, BitTiming, BtConst, DeviceConfig, DeviceMode, REQUEST_TYPE_IN, REQUEST_TYPE_OUT, Request,
};

/// The IN endpoint's address: Linux's gs_usb before 6.6 expects 0x81 and 0x02.
pub const EP_IN: u8 = 0x81;
/// The OUT endpoint's address.
pub const EP_OUT: u8 = 0x02;

/// A candleLight's constants (STM32F072, 48 MHz), without hardware timestamps: the frames stay
/// 20 bytes each way.
pub const CONSTANTS: BtConst = BtConst {
    features: 0,
    clock_hz: 48_000_000,
    tseg1_min: 1,
    tseg1_max: 16,
    tseg2_min: 1,
    tseg2_max: 8,
    sjw_max: 4,
    brp_min: 1,
    brp_max: 1024,
    brp_inc: 1,
};

/// `linux/usb/functionfs.h`: the descriptors blob, version 2, with full- and high-speed sets
/// (one vendor interface, a bulk IN and a bulk OUT endpoint).
pub fn descriptors() -> Vec<u8> {
    const MAGIC_V2: u32 = 3;
    const HAS_FS_DESC: u32 = 1;
    const HAS_HS_DESC: u32 = 2;
    let interface = [9, 4, 0, 0, 2, 0xff, 0xff, 0xff, 1];
    let endpoint = |address: u8, max_packet: u16| {
        let [lo, hi] = max_packet.to_le_bytes();
        [7, 5, address, 2, lo, hi, 0]
    };
    let set = |max_packet| {
        let mut set = interface.to_vec();
        set.extend(endpoint(EP_IN, max_packet));
        set.extend(endpoint(EP_OUT, max_packet));
        set
    };
    let (full, high) = (set(64), set(512));
    let mut blob = Vec::new();
    for word in [MAGIC_V2, 0, HAS_FS_DESC | HAS_HS_DESC, 3, 3] {
        blob.extend(word.to_le_bytes());
    }
    blob.extend(full);
    blob.extend(high);
    let length = blob.len() as u32;
    blob[4..8].copy_from_slice(&length.to_le_bytes());
    blob
}

/// The strings blob: the interface's name, in US English.
pub fn strings() -> Vec<u8> {
    const MAGIC: u32 = 2;
    let name = b"gs_usb (emulated)\0";
    let mut blob = Vec::new();
    for word in [MAGIC, 0, 1, 1] {
        blob.extend(word.to_le_bytes());
    }
    blob.extend(0x0409_u16.to_le_bytes());
    blob.extend(name);
    let length = blob.len() as u32;
    blob[4..8].copy_from_slice(&length.to_le_bytes());
    blob
}

/// The size of one `struct usb_functionfs_event`.
pub const EVENT_LEN: usize = 12;

/// One ep0 event.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Event {
    /// The function was bound to a UDC, unbound, enabled by the host's configuration,
    /// disabled, suspended or resumed.
    Other(u8),
    /// A control request for the function.
    Setup {
        /// bmRequestType.
        request_type: u8,
        /// bRequest.
        request: u8,
        /// wValue.
        value: u16,
        /// wLength.
        length: u16,
    },
}

impl Event {
    /// `FUNCTIONFS_SETUP`.
    const SETUP: u8 = 4;

    /// Reads one event.
    pub fn decode(bytes: &[u8; EVENT_LEN]) -> Self {
        if bytes[8] != Self::SETUP {
            return Self::Other(bytes[8]);
        }
        Self::Setup {
            request_type: bytes[0],
            request: bytes[1],
            value: u16::from_le_bytes([bytes[2], bytes[3]]),
            length: u16::from_le_bytes([bytes[6], bytes[7]]),
        }
    }
}

/// What to do with a control request.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Reply {
    /// Send these bytes (device to host).
    Send(Vec<u8>),
    /// Read the host's data stage, then hand it to [`Adapter::handle_data`].
    Receive(Request),
    /// Refuse (stall ep0).
    Stall,
}

/// The adapter's state: whether the channel is started, and its timing.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Adapter {
    /// The channel runs: frames from the bus go to the host.
    pub started: bool,
    /// The bit timing the host set, if any.
    pub timing: Option<BitTiming>,
    /// Requests refused, by number.
    pub refused: Vec<u8>,
}

impl Adapter {
    /// Answers a control request.
    pub fn handle_setup(&mut self, request_type: u8, request: u8, value: u16) -> Reply {
        let Some(known) = Request::from_number(request) else {
            self.refused.push(request);
            return Reply::Stall;
        };
        let expected = if known.reads() {
            REQUEST_TYPE_IN
        } else {
            REQUEST_TYPE_OUT
        };
        // One channel: 0 (the device-wide requests carry 1).
        if request_type != expected || (!known.device_wide() && value != 0) {
            self.refused.push(request);
            return Reply::Stall;
        }
        match known {
            Request::DeviceConfig => Reply::Send(
                DeviceConfig {
                    channels: 1,
                    software_version: 2,
                    hardware_version: 1,
                }
                .encode()
                .to_vec(),
            ),
            Request::BtConst => Reply::Send(CONSTANTS.encode().to_vec()),
            Request::HostFormat | Request::BitTiming | Request::Mode => Reply::Receive(known),
        }
    }

    /// Takes the data stage of a host-to-device request; `false` when it is not understood.
    pub fn handle_data(&mut self, request: Request, data: &[u8]) -> bool {
        match request {
            Request::HostFormat => data.len() >= 4,
            Request::BitTiming => match BitTiming::decode(data) {
                Ok(timing) => {
                    self.timing = Some(timing);
                    true
                }
                Err(_) => false,
            },
            Request::Mode => match DeviceMode::decode(data) {
                Ok(mode) => {
                    self.started = mode.start;
                    true
                }
                Err(_) => false,
            },
            Request::BtConst | Request::DeviceConfig => false,
        }
    }

    /// The bit rate the host set, if it set one.
    pub fn bitrate(&self) -> Option<u32> {
        self.timing.map(|t| t.bitrate(CONSTANTS.clock_hz))
    }
}

/// The host frame that carries `frame` from the bus (or an error frame's raw id and data).
pub fn from_bus(can_id: u32, data: &[u8]) -> Vec<u8> {
    let mut padded = [0; 8];
    let len = data.len().min(8);
    padded[..len].copy_from_slice(&data[..len]);
    let frame = gs_usb::HostFrame {
        echo_id: gs_usb::RX_ECHO_ID,
        can_id,
        len: len as u8,
        channel: 0,
        flags: 0,
        data: padded,
        timestamp_us: None,
    };
    let (bytes, len) = frame.encode();
    bytes[..len].to_vec()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_descriptor_blobs_say_their_length_and_counts() {
        let blob = descriptors();
        assert_eq!(
            u32::from_le_bytes(blob[4..8].try_into().unwrap()) as usize,
            blob.len()
        );
        // Header of five words, then two sets of 9 + 7 + 7 bytes.
        assert_eq!(blob.len(), 20 + 2 * 23);
        assert_eq!(&blob[20 + 9..20 + 16], &[7, 5, 0x81, 2, 64, 0, 0]);
        assert_eq!(&blob[20 + 23 + 16..], &[7, 5, 0x02, 2, 0, 2, 0]);
        let strings = strings();
        assert_eq!(
            u32::from_le_bytes(strings[4..8].try_into().unwrap()) as usize,
            strings.len()
        );
    }

    #[test]
    fn the_set_up_linux_does_is_answered_and_starts_the_channel() {
        let mut adapter = Adapter::default();
        let setup = |adapter: &mut Adapter, request: Request| {
            let setup = gs_usb::Setup::new(request, 0, 0);
            adapter.handle_setup(setup.request_type, setup.request, setup.value)
        };
        assert_eq!(
            setup(&mut adapter, Request::HostFormat),
            Reply::Receive(Request::HostFormat)
        );
        let Reply::Send(config) = setup(&mut adapter, Request::DeviceConfig) else {
            panic!("the device configuration is answered")
        };
        assert_eq!(DeviceConfig::decode(&config).unwrap().channels, 1);
        let Reply::Send(constants) = setup(&mut adapter, Request::BtConst) else {
            panic!("the constants are answered")
        };
        let constants = BtConst::decode(&constants).unwrap();
        let timing = BitTiming::for_bitrate(&constants, 500_000).unwrap();
        assert!(adapter.handle_data(Request::BitTiming, &timing.encode()));
        assert_eq!(adapter.bitrate(), Some(500_000));
        let start = DeviceMode {
            start: true,
            flags: 0,
        };
        assert!(adapter.handle_data(Request::Mode, &start.encode()));
        assert!(adapter.started);
        assert!(adapter.handle_data(Request::Mode, &DeviceMode::STOPPED.encode()));
        assert!(!adapter.started);
    }

    #[test]
    fn unknown_requests_and_other_channels_are_stalled() {
        let mut adapter = Adapter::default();
        assert_eq!(adapter.handle_setup(REQUEST_TYPE_IN, 11, 0), Reply::Stall);
        assert_eq!(
            adapter.handle_setup(REQUEST_TYPE_OUT, 2, 1),
            Reply::Stall,
            "channel 1"
        );
        assert_eq!(
            adapter.handle_setup(REQUEST_TYPE_OUT, 4, 0),
            Reply::Stall,
            "wrong way"
        );
        assert_eq!(adapter.refused, vec![11, 2, 4]);
    }

    #[test]
    fn events_decode_setups_and_others() {
        let mut bytes = [0u8; EVENT_LEN];
        bytes[..8].copy_from_slice(&[0xc1, 5, 1, 0, 0, 0, 12, 0]);
        bytes[8] = 4;
        assert_eq!(
            Event::decode(&bytes),
            Event::Setup {
                request_type: 0xc1,
                request: 5,
                value: 1,
                length: 12
            }
        );
        bytes[8] = 2;
        assert_eq!(Event::decode(&bytes), Event::Other(2));
    }
}
