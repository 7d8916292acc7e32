//! gs_usb: the host protocol of candleLight-style USB-CAN adapters (the one Linux's `gs_usb`
//! driver speaks), without I/O: the vendor control requests, the bit timing for a bit rate from
//! the adapter's constants, and the host frames on the bulk endpoints.
//!
//! Every multi-byte field is little-endian: the host says so first ([`HostConfig`]), as the
//! Linux driver does. The layouts are named byte ranges, after the protocol's definition in
//! `drivers/net/can/usb/gs_usb.c`; the golden vectors in the tests are the bytes that driver
//! exchanges with a candleLight.

use crate::can::{CanFrame, MAX_STANDARD_ID};

/// A USB vendor and product id.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct UsbId {
    /// idVendor.
    pub vendor: u16,
    /// idProduct.
    pub product: u16,
}

/// The adapters known to speak gs_usb, as Linux's driver lists them: candleLight (and the
/// adapters that reuse its ids, AgileX's among them), its pid.codes id, CES CANext FD, ABE
/// CANdebugger FD, Xylanta SAINT3 and CANnectivity.
pub const KNOWN_ADAPTERS: [UsbId; 6] = [
    UsbId {
        vendor: 0x1d50,
        product: 0x606f,
    },
    UsbId {
        vendor: 0x1209,
        product: 0x2323,
    },
    UsbId {
        vendor: 0x1cd2,
        product: 0x606f,
    },
    UsbId {
        vendor: 0x16d0,
        product: 0x10b8,
    },
    UsbId {
        vendor: 0x16d0,
        product: 0x0f30,
    },
    UsbId {
        vendor: 0x1209,
        product: 0xca01,
    },
];

/// `bmRequestType` of a request from the host: vendor, to the interface.
pub const REQUEST_TYPE_OUT: u8 = 0x41;
/// `bmRequestType` of a request answered by the device: vendor, to the interface, device to host.
pub const REQUEST_TYPE_IN: u8 = 0xc1;

/// The vendor requests the gateway uses (`bRequest`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Request {
    /// Host to device: the byte order of everything after it ([`HostConfig`]).
    HostFormat = 0,
    /// Host to device: a channel's bit timing ([`BitTiming`]).
    BitTiming = 1,
    /// Host to device: start or reset a channel ([`DeviceMode`]).
    Mode = 2,
    /// Device to host: the bit-timing constants of a channel ([`BtConst`]).
    BtConst = 4,
    /// Device to host: the number of channels and the versions ([`DeviceConfig`]).
    DeviceConfig = 5,
}

impl Request {
    /// Every request the gateway uses.
    pub const ALL: [Self; 5] = [
        Self::HostFormat,
        Self::BitTiming,
        Self::Mode,
        Self::BtConst,
        Self::DeviceConfig,
    ];

    /// The request numbered `number`, if it is one of [`Request::ALL`].
    pub fn from_number(number: u8) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|request| *request as u8 == number)
    }

    /// Whether the device answers it with data (`REQUEST_TYPE_IN`).
    pub const fn reads(self) -> bool {
        match self {
            Self::HostFormat | Self::BitTiming | Self::Mode => false,
            Self::BtConst | Self::DeviceConfig => true,
        }
    }

    /// Whether it concerns the whole device, not a channel: Linux's driver sends those with
    /// `wValue` 1.
    pub const fn device_wide(self) -> bool {
        match self {
            Self::HostFormat | Self::DeviceConfig => true,
            Self::BitTiming | Self::Mode | Self::BtConst => false,
        }
    }

    /// The length of its data stage.
    pub const fn length(self) -> u16 {
        match self {
            Self::HostFormat => HostConfig::LEN as u16,
            Self::BitTiming => BitTiming::LEN as u16,
            Self::Mode => DeviceMode::LEN as u16,
            Self::BtConst => BtConst::LEN as u16,
            Self::DeviceConfig => DeviceConfig::LEN as u16,
        }
    }
}

/// A control transfer's setup stage: `wValue` is the channel (1 for the device-wide requests),
/// `wIndex` the interface for the device-wide requests and 0 for a channel's, as Linux's driver
/// sends them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Setup {
    /// bmRequestType.
    pub request_type: u8,
    /// bRequest.
    pub request: u8,
    /// wValue: the channel (1 for the device-wide requests).
    pub value: u16,
    /// wIndex: the interface number (device-wide requests), else 0.
    pub index: u16,
    /// wLength.
    pub length: u16,
}

impl Setup {
    /// The setup of `request` for `channel` (ignored by the device-wide requests) on
    /// `interface`.
    pub const fn new(request: Request, channel: u8, interface: u8) -> Self {
        Self {
            request_type: if request.reads() {
                REQUEST_TYPE_IN
            } else {
                REQUEST_TYPE_OUT
            },
            request: request as u8,
            value: if request.device_wide() {
                1
            } else {
                channel as u16
            },
            index: if request.device_wide() {
                interface as u16
            } else {
                0
            },
            length: request.length(),
        }
    }
}

/// Why bytes from the adapter were not understood.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Error {
    /// Fewer bytes than the layout needs (`expected`, `got`).
    Short {
        /// The layout's length.
        expected: usize,
        /// What arrived.
        got: usize,
    },
    /// A data length code above 15: no CAN frame has one (9 to 15 mean 8 bytes).
    BadLength(u8),
    /// A frame of another channel than the one the gateway started.
    Channel(u8),
    /// The echo of a frame the host did not send, or whose echo already came.
    UnknownEcho(u32),
    /// A CAN FD frame: the gateway never enables FD.
    Fd,
}

impl core::fmt::Display for Error {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Short { expected, got } => {
                write!(f, "gs_usb: {got} bytes where {expected} were expected")
            }
            Self::BadLength(dlc) => {
                write!(f, "gs_usb: frame with data length code {dlc} (at most 15)")
            }
            Self::Channel(channel) => {
                write!(
                    f,
                    "gs_usb: a frame of channel {channel} (the gateway uses 0)"
                )
            }
            Self::UnknownEcho(id) => {
                write!(f, "gs_usb: the echo of frame {id}, which is not on its way")
            }
            Self::Fd => f.write_str("gs_usb: a CAN FD frame, though FD was not enabled"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for Error {}

fn u32_at(bytes: &[u8], at: usize) -> u32 {
    u32::from_le_bytes([bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]])
}

fn put_u32(bytes: &mut [u8], at: usize, value: u32) {
    bytes[at..at + 4].copy_from_slice(&value.to_le_bytes());
}

/// `words`, little-endian one after the other from the start of `bytes`: the requests' data
/// are such rows of u32.
fn put_words(bytes: &mut [u8], words: &[u32]) {
    for (chunk, word) in bytes.chunks_exact_mut(4).zip(words) {
        chunk.copy_from_slice(&word.to_le_bytes());
    }
}

fn need(bytes: &[u8], expected: usize) -> Result<(), Error> {
    if bytes.len() < expected {
        Err(Error::Short {
            expected,
            got: bytes.len(),
        })
    } else {
        Ok(())
    }
}

/// `GS_USB_BREQ_HOST_FORMAT`'s data: the byte order the host wants, 0x0000beef as the host
/// writes it (little-endian here).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HostConfig;

impl HostConfig {
    /// Its length.
    pub const LEN: usize = 4;
    /// The byte-order marker.
    pub const BYTE_ORDER: u32 = 0x0000_beef;

    /// Its bytes.
    pub const fn encode() -> [u8; Self::LEN] {
        Self::BYTE_ORDER.to_le_bytes()
    }
}

/// `GS_USB_BREQ_DEVICE_CONFIG`'s answer: 3 reserved bytes, the channel count less one, the
/// software and hardware versions.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceConfig {
    /// The number of CAN channels (1 on candleLight).
    pub channels: u16,
    /// The firmware's version.
    pub software_version: u32,
    /// The hardware's version.
    pub hardware_version: u32,
}

impl DeviceConfig {
    /// Its length.
    pub const LEN: usize = 12;
    const ICOUNT: usize = 3;
    const SW_VERSION: usize = 4;
    const HW_VERSION: usize = 8;

    /// Reads the device's answer.
    pub fn decode(bytes: &[u8]) -> Result<Self, Error> {
        need(bytes, Self::LEN)?;
        Ok(Self {
            channels: u16::from(bytes[Self::ICOUNT]) + 1,
            software_version: u32_at(bytes, Self::SW_VERSION),
            hardware_version: u32_at(bytes, Self::HW_VERSION),
        })
    }

    /// The device's bytes (for an emulated adapter). `channels` is 1..=256.
    pub fn encode(&self) -> [u8; Self::LEN] {
        let mut bytes = [0; Self::LEN];
        bytes[Self::ICOUNT] = u8::try_from(self.channels.saturating_sub(1)).unwrap_or(u8::MAX);
        put_u32(&mut bytes, Self::SW_VERSION, self.software_version);
        put_u32(&mut bytes, Self::HW_VERSION, self.hardware_version);
        bytes
    }
}

/// `GS_USB_BREQ_BT_CONST`'s answer: the channel's features, its CAN clock and the bounds of its
/// bit-timing registers (ten little-endian u32).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BtConst {
    /// Feature bits (`GS_CAN_FEATURE_*`): [`BtConst::HW_TIMESTAMP`]...
    pub features: u32,
    /// The CAN controller's clock, Hz.
    pub clock_hz: u32,
    /// Time segment 1 (propagation and phase 1), in time quanta.
    pub tseg1_min: u32,
    /// The largest time segment 1.
    pub tseg1_max: u32,
    /// Time segment 2 (phase 2), in time quanta.
    pub tseg2_min: u32,
    /// The largest time segment 2.
    pub tseg2_max: u32,
    /// The largest synchronisation jump width.
    pub sjw_max: u32,
    /// The smallest bit-rate prescaler.
    pub brp_min: u32,
    /// The largest bit-rate prescaler.
    pub brp_max: u32,
    /// The prescaler's step.
    pub brp_inc: u32,
}

impl BtConst {
    /// Its length.
    pub const LEN: usize = 40;
    /// The feature bit of hardware timestamps on received frames.
    pub const HW_TIMESTAMP: u32 = 1 << 4;
    /// The feature bit of CAN FD.
    pub const FD: u32 = 1 << 8;
    /// The feature bit of bus-error reporting on request.
    pub const BERR_REPORTING: u32 = 1 << 12;

    /// Reads the device's answer.
    pub fn decode(bytes: &[u8]) -> Result<Self, Error> {
        need(bytes, Self::LEN)?;
        let field = |i: usize| u32_at(bytes, 4 * i);
        Ok(Self {
            features: field(0),
            clock_hz: field(1),
            tseg1_min: field(2),
            tseg1_max: field(3),
            tseg2_min: field(4),
            tseg2_max: field(5),
            sjw_max: field(6),
            brp_min: field(7),
            brp_max: field(8),
            brp_inc: field(9),
        })
    }

    /// The device's bytes (for an emulated adapter).
    pub fn encode(&self) -> [u8; Self::LEN] {
        let mut bytes = [0; Self::LEN];
        put_words(
            &mut bytes,
            &[
                self.features,
                self.clock_hz,
                self.tseg1_min,
                self.tseg1_max,
                self.tseg2_min,
                self.tseg2_max,
                self.sjw_max,
                self.brp_min,
                self.brp_max,
                self.brp_inc,
            ],
        );
        bytes
    }
}

/// `GS_USB_BREQ_BITTIMING`'s data: the bit in time quanta of `brp` clock cycles, after the one
/// quantum of the sync segment.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BitTiming {
    /// Propagation segment, quanta.
    pub prop_seg: u32,
    /// Phase segment 1, quanta.
    pub phase_seg1: u32,
    /// Phase segment 2, quanta.
    pub phase_seg2: u32,
    /// Synchronisation jump width, quanta.
    pub sjw: u32,
    /// Bit-rate prescaler: clock cycles per quantum.
    pub brp: u32,
}

/// Why no bit timing fits the adapter.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BitTimingError {
    /// The constants allow no bit at all (a zero clock or prescaler step, empty ranges).
    BadConstants,
    /// The nearest bit rate the adapter can make is further than 1 % from the one asked.
    NoRate {
        /// The rate asked, bit/s.
        bitrate: u32,
        /// The adapter's clock, Hz.
        clock_hz: u32,
    },
}

impl core::fmt::Display for BitTimingError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::BadConstants => {
                f.write_str("gs_usb: the adapter's bit-timing constants allow no bit timing")
            }
            Self::NoRate { bitrate, clock_hz } => write!(
                f,
                "gs_usb: the adapter's {clock_hz} Hz clock makes no bit rate within 1 % of {bitrate} bit/s"
            ),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for BitTimingError {}

impl BitTiming {
    /// Its length.
    pub const LEN: usize = 20;
    /// The sample point CiA 301 recommends for 500 kbit/s and below, per mille of the bit.
    pub const SAMPLE_POINT: u32 = 875;

    /// The timing of `bitrate` (bit/s) on an adapter with these constants: the rate nearest
    /// `bitrate` (exact where the clock allows, never further than 1 %); among those, the sample
    /// point nearest [`BitTiming::SAMPLE_POINT`] without passing it; then the most quanta per
    /// bit (the finest resynchronisation). Phase segment 1 takes the larger half of time segment
    /// 1, and the jump width is half phase segment 2 (at least 1, at most phase segment 1 and
    /// `sjw_max`).
    pub fn for_bitrate(constants: &BtConst, bitrate: u32) -> Result<Self, BitTimingError> {
        let c = constants;
        if c.clock_hz == 0
            || bitrate == 0
            || c.brp_inc == 0
            || c.brp_min > c.brp_max
            || c.tseg1_min > c.tseg1_max
            || c.tseg2_min > c.tseg2_max
            || c.tseg1_max == 0
            || c.tseg2_max == 0
        {
            return Err(BitTimingError::BadConstants);
        }
        // (rate error, sample-point error, -quanta) of the best so far, and its timing.
        let mut best: Option<((u64, u32, i64), Self)> = None;
        let min_quanta = 1 + u64::from(c.tseg1_min.max(1)) + u64::from(c.tseg2_min.max(1));
        let max_quanta = 1 + u64::from(c.tseg1_max) + u64::from(c.tseg2_max);
        let mut brp = u64::from(c.brp_min.max(c.brp_inc)).div_ceil(u64::from(c.brp_inc))
            * u64::from(c.brp_inc);
        // Past this prescaler a bit has fewer quanta than the smallest allowed.
        let last = u64::from(c.brp_max)
            .min(u64::from(c.clock_hz) * 100 / (u64::from(bitrate) * min_quanta * 99) + 1);
        while brp <= last {
            // The quanta counts whose rate is within 1 % of the one asked (and one more each
            // side, for the roundings).
            let cycles = u64::from(c.clock_hz) * 100 / brp;
            let first = (cycles / (u64::from(bitrate) * 101))
                .saturating_sub(1)
                .max(min_quanta);
            let last_quanta = (cycles / (u64::from(bitrate) * 99) + 2).min(max_quanta);
            for quanta in first..=last_quanta {
                let rate = u64::from(c.clock_hz) / (brp * quanta);
                let rate_error = rate.abs_diff(u64::from(bitrate));
                let Some((sample_error, tseg1, tseg2)) = Self::split(c, quanta) else {
                    continue;
                };
                let key = (rate_error, sample_error, -(quanta as i64));
                if best.is_none_or(|(best_key, _)| key < best_key) {
                    let prop_seg = tseg1 / 2;
                    let phase_seg1 = tseg1 - prop_seg;
                    best = Some((
                        key,
                        Self {
                            prop_seg,
                            phase_seg1,
                            phase_seg2: tseg2,
                            sjw: (tseg2 / 2).min(phase_seg1).min(c.sjw_max).max(1),
                            brp: brp as u32,
                        },
                    ));
                }
            }
            brp += u64::from(c.brp_inc);
        }
        match best {
            Some(((rate_error, _, _), timing)) if rate_error * 100 <= u64::from(bitrate) => {
                Ok(timing)
            }
            _ => Err(BitTimingError::NoRate {
                bitrate,
                clock_hz: c.clock_hz,
            }),
        }
    }

    /// Time segments 1 and 2 of a bit of `quanta` quanta whose sample point (per mille,
    /// rounded down, as [`BitTiming::sample_point`]) is nearest [`BitTiming::SAMPLE_POINT`]
    /// without passing it, with its distance. The sample point follows sync and time segment 1,
    /// so the shortest segment 2 that keeps it at or before the ideal is the nearest: the
    /// smallest with `1000 * (quanta - tseg2) < (SAMPLE_POINT + 1) * quanta`.
    fn split(c: &BtConst, quanta: u64) -> Option<(u32, u32, u32)> {
        let ideal = (999 - u64::from(Self::SAMPLE_POINT)) * quanta / 1000 + 1;
        let tseg2 = ideal
            .max(u64::from(c.tseg2_min.max(1)))
            .max(quanta.saturating_sub(1 + u64::from(c.tseg1_max)));
        let tseg1 = quanta.checked_sub(1 + tseg2)?;
        if tseg2 > u64::from(c.tseg2_max) || tseg1 < u64::from(c.tseg1_min.max(1)) {
            return None;
        }
        let sample_point = 1000 * (quanta - tseg2) / quanta;
        let error = u64::from(Self::SAMPLE_POINT).saturating_sub(sample_point);
        Some((error as u32, tseg1 as u32, tseg2 as u32))
    }

    /// The bit rate it makes on a `clock_hz` clock, bit/s.
    pub fn bitrate(&self, clock_hz: u32) -> u32 {
        (u64::from(clock_hz) / (u64::from(self.brp.max(1)) * self.quanta())) as u32
    }

    /// Its sample point, per mille of the bit.
    pub fn sample_point(&self) -> u32 {
        let quanta = self.quanta();
        (1000 * quanta.saturating_sub(u64::from(self.phase_seg2)) / quanta) as u32
    }

    /// Quanta per bit: sync, propagation, phase 1, phase 2.
    fn quanta(&self) -> u64 {
        1 + u64::from(self.prop_seg) + u64::from(self.phase_seg1) + u64::from(self.phase_seg2)
    }

    /// Its bytes.
    pub fn encode(&self) -> [u8; Self::LEN] {
        let mut bytes = [0; Self::LEN];
        put_words(
            &mut bytes,
            &[
                self.prop_seg,
                self.phase_seg1,
                self.phase_seg2,
                self.sjw,
                self.brp,
            ],
        );
        bytes
    }

    /// Reads it (for an emulated adapter).
    pub fn decode(bytes: &[u8]) -> Result<Self, Error> {
        need(bytes, Self::LEN)?;
        Ok(Self {
            prop_seg: u32_at(bytes, 0),
            phase_seg1: u32_at(bytes, 4),
            phase_seg2: u32_at(bytes, 8),
            sjw: u32_at(bytes, 12),
            brp: u32_at(bytes, 16),
        })
    }
}

/// `GS_USB_BREQ_MODE`'s data: start or reset a channel, with mode flags.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceMode {
    /// Start (true) or reset (false) the channel.
    pub start: bool,
    /// `GS_CAN_MODE_*` flags: [`DeviceMode::HW_TIMESTAMP`]...
    pub flags: u32,
}

impl DeviceMode {
    /// Its length.
    pub const LEN: usize = 8;
    /// Reset the channel (stop it).
    pub const STOPPED: Self = Self {
        start: false,
        flags: 0,
    };
    /// The flag asking for hardware timestamps on received frames (the frames grow by 4 bytes).
    pub const HW_TIMESTAMP: u32 = 1 << 4;
    const RESET: u32 = 0;
    const START: u32 = 1;

    /// Its bytes.
    pub fn encode(&self) -> [u8; Self::LEN] {
        let mode = if self.start { Self::START } else { Self::RESET };
        let mut bytes = [0; Self::LEN];
        put_words(&mut bytes, &[mode, self.flags]);
        bytes
    }

    /// Reads it (for an emulated adapter); a mode other than start is a reset.
    pub fn decode(bytes: &[u8]) -> Result<Self, Error> {
        need(bytes, Self::LEN)?;
        Ok(Self {
            start: u32_at(bytes, 0) == Self::START,
            flags: u32_at(bytes, 4),
        })
    }
}

/// The `echo_id` of a frame the adapter received from the bus (not the echo of one sent).
pub const RX_ECHO_ID: u32 = 0xffff_ffff;

/// A classic host frame: echo id, CAN id with flags, data length code, channel, flags, a
/// reserved byte, 8 data bytes; and the hardware timestamp (µs) when the mode asked for it.
pub mod frame {
    use core::ops::Range;
    /// `echo_id`: [`super::RX_ECHO_ID`] for a received frame, the host's id in a sent one's echo.
    pub const ECHO_ID: Range<usize> = 0..4;
    /// `can_id`: the id and the EFF, RTR and ERR flags, as SocketCAN's.
    pub const CAN_ID: Range<usize> = 4..8;
    /// `can_dlc`.
    pub const DLC: usize = 8;
    /// `channel`.
    pub const CHANNEL: usize = 9;
    /// `flags`: [`OVERFLOW`], FD bits.
    pub const FLAGS: usize = 10;
    /// `data`.
    pub const DATA: Range<usize> = 12..20;
    /// `timestamp_us`, with hardware timestamps.
    pub const TIMESTAMP: Range<usize> = 20..24;
    /// Without a timestamp.
    pub const LEN: usize = 20;
    /// With one.
    pub const LEN_TIMESTAMPED: usize = 24;
    /// The flag of a frame after which the adapter lost received frames.
    pub const OVERFLOW: u8 = 1 << 0;
    /// The flag of a CAN FD frame.
    pub const FD: u8 = 1 << 1;
    /// `can_id`'s flag of an extended (29-bit) id.
    pub const EFF: u32 = 0x8000_0000;
    /// `can_id`'s flag of a remote frame.
    pub const RTR: u32 = 0x4000_0000;
    /// `can_id`'s flag of an error frame.
    pub const ERR: u32 = 0x2000_0000;
}

/// What a host frame from the adapter's bulk IN endpoint says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Received {
    /// A standard data frame from the bus.
    Frame(CanFrame),
    /// The adapter put the host's frame with this echo id on the bus.
    Echo(u32),
    /// An extended-id or remote frame (SCOUT sends none): its raw `can_id`.
    Foreign(u32),
    /// An error frame: `linux/can/error.h`'s class bits and data, as SocketCAN gives them.
    BusError {
        /// The class bits of `can_id` (bus-off 0x40, controller 0x04, ...).
        class: u32,
        /// The error frame's data (byte 1: the controller's state).
        data: [u8; 8],
    },
}

/// One classic host frame, either way: the host's to send, or the adapter's (a frame from the
/// bus, the echo of one sent, an error frame).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HostFrame {
    /// [`RX_ECHO_ID`] for a frame from the bus, else the host's id of the frame it sent.
    pub echo_id: u32,
    /// The id with SocketCAN's EFF, RTR and ERR flags.
    pub can_id: u32,
    /// The data length code, 0..=15: above 8 it means 8 bytes (classic CAN, as Linux reads
    /// it).
    pub len: u8,
    /// The channel.
    pub channel: u8,
    /// [`frame::OVERFLOW`]: the adapter lost received frames before this one.
    pub flags: u8,
    /// The data; only the first `len` bytes count.
    pub data: [u8; 8],
    /// The adapter's timestamp, µs (wraps at 2³²), when the mode asked for them.
    pub timestamp_us: Option<u32>,
}

impl HostFrame {
    /// The host's frame that sends `frame` on `channel`; the adapter echoes `echo_id` back once
    /// the frame is on the bus (it must not be [`RX_ECHO_ID`]).
    pub fn transmit(frame: &CanFrame, channel: u8, echo_id: u32) -> Self {
        let mut data = [0; 8];
        data[..frame.data().len()].copy_from_slice(frame.data());
        Self {
            echo_id,
            can_id: u32::from(frame.id()),
            len: frame.data().len() as u8,
            channel,
            flags: 0,
            data,
            timestamp_us: None,
        }
    }

    /// Reads one host frame; `timestamped` when the mode asked for hardware timestamps (then
    /// it is 24 bytes). Bytes after the frame (padding) are ignored.
    pub fn decode(bytes: &[u8], timestamped: bool) -> Result<Self, Error> {
        need(
            bytes,
            if timestamped {
                frame::LEN_TIMESTAMPED
            } else {
                frame::LEN
            },
        )?;
        let flags = bytes[frame::FLAGS];
        if flags & frame::FD != 0 {
            return Err(Error::Fd);
        }
        let len = bytes[frame::DLC];
        if len > 15 {
            return Err(Error::BadLength(len));
        }
        let mut data = [0; 8];
        data.copy_from_slice(&bytes[frame::DATA]);
        Ok(Self {
            echo_id: u32_at(bytes, frame::ECHO_ID.start),
            can_id: u32_at(bytes, frame::CAN_ID.start),
            len,
            channel: bytes[frame::CHANNEL],
            flags,
            data,
            timestamp_us: timestamped.then(|| u32_at(bytes, frame::TIMESTAMP.start)),
        })
    }

    /// Its bytes, and how many of them count (24 with a timestamp, else 20).
    pub fn encode(&self) -> ([u8; frame::LEN_TIMESTAMPED], usize) {
        let mut bytes = [0; frame::LEN_TIMESTAMPED];
        bytes[frame::ECHO_ID].copy_from_slice(&self.echo_id.to_le_bytes());
        bytes[frame::CAN_ID].copy_from_slice(&self.can_id.to_le_bytes());
        bytes[frame::DLC] = self.len;
        bytes[frame::CHANNEL] = self.channel;
        bytes[frame::FLAGS] = self.flags;
        bytes[frame::DATA].copy_from_slice(&self.data);
        match self.timestamp_us {
            Some(us) => {
                bytes[frame::TIMESTAMP].copy_from_slice(&us.to_le_bytes());
                (bytes, frame::LEN_TIMESTAMPED)
            }
            None => (bytes, frame::LEN),
        }
    }

    /// The standard data frame it carries, if that is what it carries (whatever its echo id).
    pub fn can_frame(&self) -> Option<CanFrame> {
        if self.can_id & (frame::EFF | frame::RTR | frame::ERR) != 0
            || self.can_id > u32::from(MAX_STANDARD_ID)
        {
            return None;
        }
        CanFrame::new(
            self.can_id as u16,
            &self.data[..usize::from(self.len.min(8))],
        )
    }

    /// What it says, read as the adapter's frame.
    pub fn received(&self) -> Received {
        if self.echo_id != RX_ECHO_ID {
            Received::Echo(self.echo_id)
        } else if self.can_id & frame::ERR != 0 {
            Received::BusError {
                class: self.can_id & !(frame::EFF | frame::RTR | frame::ERR),
                data: self.data,
            }
        } else {
            self.can_frame()
                .map_or(Received::Foreign(self.can_id), Received::Frame)
        }
    }

    /// Whether the adapter lost received frames before this one.
    pub fn overflow(&self) -> bool {
        self.flags & frame::OVERFLOW != 0
    }
}

#[cfg(test)]
mod tests {
    //! Golden vectors: the bytes Linux's gs_usb driver and a candleLight (STM32F072, 48 MHz CAN
    //! clock) exchange.
    use super::*;

    /// A candleLight's constants: hardware timestamps, listen-only, loop-back, identify; time
    /// segment 1 of 1..16, 2 of 1..8, jump width up to 4, prescaler 1..1024.
    const CANDLELIGHT: BtConst = BtConst {
        features: 0x33,
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

    fn scout_frame() -> CanFrame {
        CanFrame::new(0x130, &[0x01, 0, 0x0a, 0, 0, 0, 0, 0x44]).expect("a valid frame")
    }

    #[test]
    fn the_setup_stages_are_the_linux_drivers() {
        let setup = |request, channel| {
            let s = Setup::new(request, channel, 0);
            (s.request_type, s.request, s.value, s.index, s.length)
        };
        assert_eq!(setup(Request::HostFormat, 0), (0x41, 0, 1, 0, 4));
        assert_eq!(setup(Request::DeviceConfig, 0), (0xc1, 5, 1, 0, 12));
        assert_eq!(setup(Request::BtConst, 0), (0xc1, 4, 0, 0, 40));
        assert_eq!(setup(Request::BitTiming, 0), (0x41, 1, 0, 0, 20));
        assert_eq!(setup(Request::Mode, 1), (0x41, 2, 1, 0, 8));
        // wIndex: the interface for the device-wide requests, 0 for a channel's.
        assert_eq!(Setup::new(Request::HostFormat, 0, 3).index, 3);
        assert_eq!(Setup::new(Request::DeviceConfig, 0, 3).index, 3);
        assert_eq!(Setup::new(Request::Mode, 0, 3).index, 0);
        for request in Request::ALL {
            assert_eq!(Request::from_number(request as u8), Some(request));
        }
        assert_eq!(Request::from_number(3), None);
    }

    #[test]
    fn the_host_format_is_0000beef_little_endian() {
        assert_eq!(HostConfig::encode(), [0xef, 0xbe, 0x00, 0x00]);
    }

    #[test]
    fn a_candlelights_device_config_reads_and_writes_back() {
        let bytes = [0, 0, 0, 0, 2, 0, 0, 0, 1, 0, 0, 0];
        let config = DeviceConfig::decode(&bytes).expect("12 bytes");
        assert_eq!(
            config,
            DeviceConfig {
                channels: 1,
                software_version: 2,
                hardware_version: 1
            }
        );
        assert_eq!(config.encode(), bytes);
        assert_eq!(
            DeviceConfig::decode(&bytes[..11]),
            Err(Error::Short {
                expected: 12,
                got: 11
            })
        );
    }

    #[test]
    fn a_candlelights_constants_read_and_write_back() {
        let bytes = CANDLELIGHT.encode();
        assert_eq!(bytes[..8], [0x33, 0, 0, 0, 0x00, 0x6c, 0xdc, 0x02]);
        assert_eq!(BtConst::decode(&bytes), Ok(CANDLELIGHT));
        assert!(BtConst::decode(&bytes[..39]).is_err());
    }

    #[test]
    fn five_hundred_kbit_on_a_candlelight_is_what_linux_computes() {
        // `ip -details link show can0` on a candleLight at 500000: tq 125 ns, prop-seg 6,
        // phase-seg1 7, phase-seg2 2, sjw 1, brp 6; sample point 0.875.
        let timing = BitTiming::for_bitrate(&CANDLELIGHT, 500_000).expect("a timing");
        assert_eq!(
            timing,
            BitTiming {
                prop_seg: 6,
                phase_seg1: 7,
                phase_seg2: 2,
                sjw: 1,
                brp: 6
            }
        );
        assert_eq!(timing.bitrate(48_000_000), 500_000);
        assert_eq!(timing.sample_point(), 875);
        assert_eq!(
            timing.encode(),
            [6, 0, 0, 0, 7, 0, 0, 0, 2, 0, 0, 0, 1, 0, 0, 0, 6, 0, 0, 0]
        );
        assert_eq!(BitTiming::decode(&timing.encode()), Ok(timing));
    }

    #[test]
    fn an_80_mhz_fd_controller_gets_the_finest_exact_timing() {
        // An FDCAN's nominal constants (STM32G4 at 80 MHz): of the exact timings (160 quanta
        // at prescaler 1, 80 at 2, ...), the one with the most quanta, sample point 87.5 %.
        let fdcan = BtConst {
            clock_hz: 80_000_000,
            tseg1_max: 256,
            tseg2_max: 128,
            sjw_max: 128,
            brp_max: 512,
            ..CANDLELIGHT
        };
        let timing = BitTiming::for_bitrate(&fdcan, 500_000).expect("a timing");
        assert_eq!(
            timing,
            BitTiming {
                prop_seg: 69,
                phase_seg1: 70,
                phase_seg2: 20,
                sjw: 10,
                brp: 1
            }
        );
    }

    #[test]
    fn a_clock_that_makes_no_rate_within_one_percent_is_refused() {
        // 1 MHz at 500 kbit/s: 2 quanta a bit, below the 3 (sync, 1, 1) a bit needs.
        let slow = BtConst {
            clock_hz: 1_000_000,
            ..CANDLELIGHT
        };
        assert_eq!(
            BitTiming::for_bitrate(&slow, 500_000),
            Err(BitTimingError::NoRate {
                bitrate: 500_000,
                clock_hz: 1_000_000
            })
        );
        let broken = BtConst {
            brp_inc: 0,
            ..CANDLELIGHT
        };
        assert_eq!(
            BitTiming::for_bitrate(&broken, 500_000),
            Err(BitTimingError::BadConstants)
        );
    }

    #[test]
    fn start_with_hardware_timestamps() {
        let mode = DeviceMode {
            start: true,
            flags: DeviceMode::HW_TIMESTAMP,
        };
        assert_eq!(mode.encode(), [1, 0, 0, 0, 0x10, 0, 0, 0]);
        assert_eq!(DeviceMode::decode(&mode.encode()), Ok(mode));
        let reset = DeviceMode {
            start: false,
            flags: 0,
        };
        assert_eq!(reset.encode(), [0; 8]);
    }

    #[test]
    fn a_motion_command_as_the_host_sends_it() {
        let (bytes, len) = HostFrame::transmit(&scout_frame(), 0, 7).encode();
        assert_eq!(
            bytes[..len],
            [
                7, 0, 0, 0, 0x30, 0x01, 0, 0, 8, 0, 0, 0, 0x01, 0, 0x0a, 0, 0, 0, 0, 0x44
            ]
        );
        // The adapter reads the frame back out of it.
        let host = HostFrame::decode(&bytes[..len], false).expect("20 bytes");
        assert_eq!(host.can_frame(), Some(scout_frame()));
        assert_eq!(host.received(), Received::Echo(7));
    }

    #[test]
    fn received_frames_echoes_and_errors_decode() {
        let mut rx = [0u8; 24];
        rx[..4].copy_from_slice(&RX_ECHO_ID.to_le_bytes());
        rx[4..8].copy_from_slice(&0x151u32.to_le_bytes());
        rx[8] = 8;
        rx[12..20].copy_from_slice(&[0x01, 0, 0x0a, 0, 0, 0, 0, 0x44]);
        rx[20..24].copy_from_slice(&1_000_000u32.to_le_bytes());
        let frame = HostFrame::decode(&rx, true).expect("a frame");
        let expected = CanFrame::new(0x151, &[0x01, 0, 0x0a, 0, 0, 0, 0, 0x44]).expect("valid");
        assert_eq!(frame.received(), Received::Frame(expected));
        assert_eq!(frame.timestamp_us, Some(1_000_000));
        assert!(!frame.overflow());
        assert_eq!(frame.encode(), (rx, 24));
        // Without timestamps the same 20 bytes, and what follows is ignored.
        assert_eq!(
            HostFrame::decode(&rx, false).expect("a frame").timestamp_us,
            None
        );

        // Bus-off: CAN_ERR_FLAG | CAN_ERR_BUSOFF, as the adapter reports it, after an overflow.
        let mut bus_off = [0u8; 20];
        bus_off[..4].copy_from_slice(&RX_ECHO_ID.to_le_bytes());
        bus_off[4..8].copy_from_slice(&0x2000_0040u32.to_le_bytes());
        bus_off[8] = 8;
        bus_off[10] = frame::OVERFLOW;
        let decoded = HostFrame::decode(&bus_off, false).expect("an error frame");
        assert_eq!(
            decoded.received(),
            Received::BusError {
                class: 0x40,
                data: [0; 8]
            }
        );
        assert!(decoded.overflow());

        let mut extended = rx;
        extended[4..8].copy_from_slice(&(0x8000_0000u32 | 0x18ff_0000).to_le_bytes());
        assert_eq!(
            HostFrame::decode(&extended, false)
                .expect("a frame")
                .received(),
            Received::Foreign(0x98ff_0000)
        );
    }

    #[test]
    fn short_long_and_fd_frames_are_errors() {
        let (mut rx, _) = HostFrame::transmit(&scout_frame(), 0, RX_ECHO_ID).encode();
        assert_eq!(
            HostFrame::decode(&rx[..19], false),
            Err(Error::Short {
                expected: 20,
                got: 19
            })
        );
        assert!(HostFrame::decode(&rx[..20], true).is_err());
        // Length codes 9 to 15 are 8 bytes, as Linux reads them; above is no CAN frame.
        rx[8] = 9;
        let nine = HostFrame::decode(&rx, false).expect("a length code of 9");
        assert_eq!(nine.can_frame().map(|f| f.data().len()), Some(8));
        assert_eq!(nine.encode().0[8], 9, "kept as it came");
        rx[8] = 16;
        assert_eq!(HostFrame::decode(&rx, false), Err(Error::BadLength(16)));
        rx[8] = 8;
        rx[10] = frame::FD;
        assert_eq!(HostFrame::decode(&rx, false), Err(Error::Fd));
    }
}
