//! The 16 fault bits of the 0x151 system status: names, and warnings told from latched protections.

/// How a fault behaves on the chassis.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Severity {
    /// Informative; clears itself when the cause goes away.
    Warning,
    /// A fault the chassis reports while the cause lasts (drive may be cut).
    Fault,
    /// Latched: the chassis stops, ignores motion and keeps the bit until the matching
    /// fault-clear code arrives in 0x130 byte 1.
    Protection,
    /// A bit the manual reserves.
    Reserved,
}

/// One fault bit, named by its position in the fault word (byte 4 is the high byte).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
#[repr(u8)]
pub enum Fault {
    /// Byte 5 bit 0: battery under-voltage fault (22 V).
    BatteryUndervoltageFault = 0,
    /// Byte 5 bit 1: battery over-voltage fault.
    BatteryOvervoltageFault = 1,
    /// Byte 5 bit 2: motor 1 communication fault.
    Motor1CommFault = 2,
    /// Byte 5 bit 3: motor 2 communication fault.
    Motor2CommFault = 3,
    /// Byte 5 bit 4: motor 3 communication fault.
    Motor3CommFault = 4,
    /// Byte 5 bit 5: motor 4 communication fault.
    Motor4CommFault = 5,
    /// Byte 5 bit 6: motor driver over-temperature protection (65 C), latched.
    DriverOvertempProtection = 6,
    /// Byte 5 bit 7: motor over-current protection (20 A rms), latched.
    MotorOvercurrentProtection = 7,
    /// Byte 4 bit 0: a command frame had a bad checksum.
    CommandChecksumError = 8,
    /// Byte 4 bit 1: motor driver over-temperature warning (55 C).
    DriverOvertempWarning = 9,
    /// Byte 4 bit 2: motor over-current warning (15 A rms).
    MotorOvercurrentWarning = 10,
    /// Byte 4 bit 3: battery under-voltage warning (22.5 V).
    BatteryUndervoltageWarning = 11,
    /// Byte 4 bit 4: RC signal lost (later manual revisions; reserved in v1.2).
    RcSignalLost = 12,
    /// Byte 4 bit 5: reserved.
    Reserved13 = 13,
    /// Byte 4 bit 6: reserved.
    Reserved14 = 14,
    /// Byte 4 bit 7: reserved.
    Reserved15 = 15,
}

impl Fault {
    /// All 16 bits in the order `scout decode` lists them (byte 4 first, then byte 5).
    pub const ALL: [Fault; 16] = [
        Self::CommandChecksumError,
        Self::DriverOvertempWarning,
        Self::MotorOvercurrentWarning,
        Self::BatteryUndervoltageWarning,
        Self::RcSignalLost,
        Self::Reserved13,
        Self::Reserved14,
        Self::Reserved15,
        Self::BatteryUndervoltageFault,
        Self::BatteryOvervoltageFault,
        Self::Motor1CommFault,
        Self::Motor2CommFault,
        Self::Motor3CommFault,
        Self::Motor4CommFault,
        Self::DriverOvertempProtection,
        Self::MotorOvercurrentProtection,
    ];

    /// The bit's mask in the fault word.
    pub const fn mask(self) -> u16 {
        1 << self as u8
    }

    /// The snake_case name used in JSON and logs.
    pub const fn name(self) -> &'static str {
        match self {
            Self::CommandChecksumError => "command_checksum_error",
            Self::DriverOvertempWarning => "driver_overtemp_warning",
            Self::MotorOvercurrentWarning => "motor_overcurrent_warning",
            Self::BatteryUndervoltageWarning => "battery_undervoltage_warning",
            Self::RcSignalLost => "rc_signal_lost",
            Self::Reserved13 => "reserved_13",
            Self::Reserved14 => "reserved_14",
            Self::Reserved15 => "reserved_15",
            Self::BatteryUndervoltageFault => "battery_undervoltage_fault",
            Self::BatteryOvervoltageFault => "battery_overvoltage_fault",
            Self::Motor1CommFault => "motor_1_comm_fault",
            Self::Motor2CommFault => "motor_2_comm_fault",
            Self::Motor3CommFault => "motor_3_comm_fault",
            Self::Motor4CommFault => "motor_4_comm_fault",
            Self::DriverOvertempProtection => "driver_overtemp_protection",
            Self::MotorOvercurrentProtection => "motor_overcurrent_protection",
        }
    }

    /// Warning, fault, latched protection or reserved.
    pub const fn severity(self) -> Severity {
        match self {
            Self::CommandChecksumError
            | Self::DriverOvertempWarning
            | Self::MotorOvercurrentWarning
            | Self::BatteryUndervoltageWarning
            | Self::RcSignalLost => Severity::Warning,
            Self::BatteryUndervoltageFault
            | Self::BatteryOvervoltageFault
            | Self::Motor1CommFault
            | Self::Motor2CommFault
            | Self::Motor3CommFault
            | Self::Motor4CommFault => Severity::Fault,
            Self::DriverOvertempProtection | Self::MotorOvercurrentProtection => {
                Severity::Protection
            }
            Self::Reserved13 | Self::Reserved14 | Self::Reserved15 => Severity::Reserved,
        }
    }
}

/// The 16-bit fault word of 0x151 (byte 4 high, byte 5 low).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct FaultBits(pub u16);

impl FaultBits {
    /// No fault.
    pub const NONE: FaultBits = FaultBits(0);

    /// Whether `fault` is set.
    pub const fn contains(self, fault: Fault) -> bool {
        self.0 & fault.mask() != 0
    }

    /// This word with `fault` set or cleared.
    #[must_use]
    pub const fn with(self, fault: Fault, set: bool) -> Self {
        if set {
            Self(self.0 | fault.mask())
        } else {
            Self(self.0 & !fault.mask())
        }
    }

    /// The set faults, in [`Fault::ALL`] order.
    pub fn iter(self) -> impl Iterator<Item = Fault> {
        Fault::ALL
            .into_iter()
            .filter(move |fault| self.contains(*fault))
    }

    /// Whether any latched protection is set (the chassis ignores motion until it is cleared).
    pub fn any_protection(self) -> bool {
        self.iter()
            .any(|fault| fault.severity() == Severity::Protection)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_bit_has_one_distinct_name() {
        let mut mask = 0u16;
        for fault in Fault::ALL {
            assert_eq!(mask & fault.mask(), 0, "{} repeats a bit", fault.name());
            mask |= fault.mask();
        }
        assert_eq!(mask, u16::MAX);
    }

    #[test]
    fn capture_word_is_the_four_motor_comm_faults() {
        let names: Vec<_> = FaultBits(0x003C).iter().map(Fault::name).collect();
        assert_eq!(
            names,
            [
                "motor_1_comm_fault",
                "motor_2_comm_fault",
                "motor_3_comm_fault",
                "motor_4_comm_fault"
            ]
        );
    }

    #[test]
    fn protections_are_the_two_latched_bits() {
        let latched: Vec<_> = Fault::ALL
            .into_iter()
            .filter(|f| f.severity() == Severity::Protection)
            .collect();
        assert_eq!(
            latched,
            [
                Fault::DriverOvertempProtection,
                Fault::MotorOvercurrentProtection
            ]
        );
        assert!(FaultBits(0x0080).any_protection());
        assert!(!FaultBits(0x0F3F).any_protection());
    }
}
