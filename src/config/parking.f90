!> The `&parking` group: the attempts of the parking and the contact test (docs/parking.md).
!>
!>     &parking max_locations = 2000, contact_method = 'eob', placement = 'uniform' /
!>
!> Validates: max_locations, max_orientations, max_sizes, max_shapes, max_failures >= 1;
!> n_ext, n_box >= 2; 1e-4 <= contact_gap <= 0.05; contact_method 'eob' or 'newton_raphson'
!> (resolved to `contact_method%...`); placement 'uniform' or 'void' (resolved to `placement%...`);
!> strategy 'rsa' or 'dense' (resolved to `parking_strategy%...`); dense_rounds, dense_sweeps >= 1;
!> 0 < dense_target_acceptance < 1; dense_time_limit >= 0; 0 <= dense_grow_scale < 1;
!> 0 <= dense_overfill <= 1; dense_max_failures >= 0; last_particle 'closer' or 'overshoot' (resolved to
!> `last_particle%...`); sieve_carry 'rounding' or 'none' (resolved to `sieve_carry%...`). The
!> strategy and the dense variables are dumped only for 'dense', contact_gap, dense_overfill,
!> dense_max_failures, last_particle and sieve_carry only when not their default
!> (a run's resolved text is unchanged by options it does not use).
!>
!> Usage:
!>     call load_parking_config(parking, nml, error)
!>     if (parking%placement == placement%void) ...
module anm_config_parking
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type
   use anm_core_strings, only: to_string, to_lower
   use anm_contact_overlap, only: contact_method
   use anm_config_namelist, only: namelist_file_type, find_group, config_error, group_read_error, max_line
   use anm_config_format, only: logical_text
   implicit none
   private

   public :: parking_config_type, load_parking_config, dump_parking_config, placement, contact_method, &
      & placement_name, contact_method_name, parking_strategy, strategy_name, last_particle, sieve_carry, &
      & last_particle_name, sieve_carry_name

   !> Placement of candidate centres.
   type :: placement_enum
      !> Uniform in the box (the thesis).
      integer :: uniform = 1
      !> Drawn from the free space of a void grid.
      integer :: void = 2
   end type placement_enum

   !> The placements, used as `placement%void`.
   type(placement_enum), parameter :: placement = placement_enum()

   !> Placement strategies.
   type :: parking_strategy_enum
      !> Random sequential addition (the thesis, anm_parking_rsa).
      integer :: rsa = 1
      !> RSA with relaxation sweeps of hard-particle Monte Carlo moves (anm_parking_dense).
      integer :: dense = 2
   end type parking_strategy_enum

   !> The strategies, used as `parking_strategy%dense`.
   type(parking_strategy_enum), parameter :: parking_strategy = parking_strategy_enum()

   !> The rule for the particle that would take a sieve past its target volume.
   type :: last_particle_enum
      !> Kept only if it brings the sieve's volume closer to the target (ours, the default).
      integer :: closer = 1
      !> Always kept: the sieve ends at or above its target (the thesis, Tables 2.1 and 2.3).
      integer :: overshoot = 2
   end type last_particle_enum

   !> The last-particle rules, used as `last_particle%overshoot`.
   type(last_particle_enum), parameter :: last_particle = last_particle_enum()

   !> What moves to the next sieve when a sieve reaches its target.
   type :: sieve_carry_enum
      !> The rounding difference (target minus parked volume, either sign; the default).
      integer :: rounding = 1
      !> Nothing: every sieve aims at its own prescribed volume (the thesis).
      integer :: none = 2
   end type sieve_carry_enum

   !> The carry rules, used as `sieve_carry%none`.
   type(sieve_carry_enum), parameter :: sieve_carry = sieve_carry_enum()

   !> The parking.
   type :: parking_config_type
      !> The thesis' four randomness sources.
      integer :: max_locations = 2000, max_orientations = 1, max_sizes = 1, max_shapes = 1
      !> Particles of a sieve that may exhaust all their attempts before the sieve ends.
      integer :: max_failures = 1
      !> Contact method, one of `contact_method`.
      integer :: contact_method = contact_method%eob
      !> N_ext and N_box of the contact test.
      integer :: n_ext = 40, n_box = 128
      !> Certified contact.
      logical :: certified = .true.
      !> Certified mode: relative gap resolution (pairs closer than contact_gap x the smaller
      !> particle's length may be refused; contact_params_type%gap).
      real(wp) :: contact_gap = 1.0e-3_wp
      !> Placement of candidate centres, one of `placement`.
      integer :: placement = placement%uniform
      !> Placement strategy, one of `parking_strategy`.
      integer :: strategy = parking_strategy%rsa
      !> Dense: relaxation-and-insertion rounds per sieve, sweeps per round.
      integer :: dense_rounds = 20, dense_sweeps = 10
      !> Dense: acceptance ratio the move sizes are tuned to.
      real(wp) :: dense_target_acceptance = 0.3_wp
      !> Dense: wall-clock limit (s) after which no new round starts (0: none; not deterministic).
      real(wp) :: dense_time_limit = 0.0_wp
      !> Dense: a round's insertions park at this fraction of their drawn width and grow (0: no growth).
      real(wp) :: dense_grow_scale = 0.0_wp
      !> Dense with growth: a round asks for its missing volume times (1 + dense_overfill); growth
      !> ends once the particles kept hold the sieve's volume.
      real(wp) :: dense_overfill = 0.0_wp
      !> Dense: particles that may exhaust their attempts before an RSA pass of the dense strategy
      !> ends (0: max_failures).
      integer :: dense_max_failures = 0
      !> Rule for a sieve's last particle, one of `last_particle`.
      integer :: last_particle = last_particle%closer
      !> What a sieve that reached its target passes to the next one, one of `sieve_carry`.
      integer :: sieve_carry = sieve_carry%rounding
   end type parking_config_type

contains

   !> Read and validate `&parking` (optional: defaults).
   !> Length: about 150 lines: one namelist read, one check per variable (each naming its line), and the
   !> enumerated keywords resolved; splitting it would spread the group over several procedures.
   subroutine load_parking_config(self, nml, error)
      !> The parking.
      type(parking_config_type), intent(out) :: self
      !> The scanned namelist file.
      type(namelist_file_type), intent(in) :: nml
      !> Error naming file, line, group and variable.
      type(error_type), allocatable, intent(out) :: error
      integer :: max_locations, max_orientations, max_sizes, max_shapes, max_failures, n_ext, n_box
      character(len=32) :: contact_method
      character(len=16) :: placement, strategy, last_particle, sieve_carry
      logical :: certified
      integer :: dense_rounds, dense_sweeps, dense_max_failures
      real(wp) :: dense_target_acceptance, dense_time_limit, dense_grow_scale, dense_overfill, contact_gap
      namelist /parking/ max_locations, max_orientations, max_sizes, max_shapes, max_failures, contact_method, &
         n_ext, n_box, certified, contact_gap, placement, strategy, dense_rounds, dense_sweeps, dense_target_acceptance, &
         dense_time_limit, dense_grow_scale, dense_overfill, dense_max_failures, last_particle, sieve_carry
      integer :: ig, stat
      character(len=512) :: msg
      character(len=max_line), allocatable :: lines(:)

      max_locations = self%max_locations
      max_orientations = self%max_orientations
      max_sizes = self%max_sizes
      max_shapes = self%max_shapes
      max_failures = self%max_failures
      contact_method = contact_method_name(self%contact_method)
      n_ext = self%n_ext
      n_box = self%n_box
      certified = self%certified
      contact_gap = self%contact_gap
      placement = placement_name(self%placement)
      strategy = strategy_name(self%strategy)
      dense_rounds = self%dense_rounds
      dense_sweeps = self%dense_sweeps
      dense_target_acceptance = self%dense_target_acceptance
      dense_time_limit = self%dense_time_limit
      dense_grow_scale = self%dense_grow_scale
      dense_overfill = self%dense_overfill
      dense_max_failures = self%dense_max_failures
      last_particle = last_particle_name(self%last_particle)
      sieve_carry = sieve_carry_name(self%sieve_carry)
      ig = find_group(nml, "parking")
      if (ig > 0) then
         lines = nml%groups(ig)%lines
         read (lines, nml=parking, iostat=stat, iomsg=msg)
         if (stat /= 0) then
            call group_read_error(error, nml, ig, msg, reader)
            return
         end if
      end if
      call at_least("max_locations", max_locations, 1)
      call at_least("max_orientations", max_orientations, 1)
      call at_least("max_sizes", max_sizes, 1)
      call at_least("max_shapes", max_shapes, 1)
      call at_least("max_failures", max_failures, 1)
      call at_least("n_ext", n_ext, 2)
      call at_least("n_box", n_box, 2)
      call at_least("dense_rounds", dense_rounds, 1)
      call at_least("dense_sweeps", dense_sweeps, 1)
      call at_least("dense_max_failures", dense_max_failures, 0)
      if (allocated(error)) return
      if (.not. (dense_target_acceptance > 0.0_wp .and. dense_target_acceptance < 1.0_wp)) then
         call config_error(error, nml, ig, "parking", "dense_target_acceptance", "= "//to_string(dense_target_acceptance) &
                           //" must be in (0, 1)")
         return
      end if
      if (.not. (dense_time_limit >= 0.0_wp)) then
         call config_error(error, nml, ig, "parking", "dense_time_limit", "= "//to_string(dense_time_limit) &
                           //" must be >= 0")
         return
      end if
      self%dense_rounds = dense_rounds
      self%dense_sweeps = dense_sweeps
      self%dense_target_acceptance = dense_target_acceptance
      if (.not. (dense_grow_scale >= 0.0_wp .and. dense_grow_scale < 1.0_wp)) then
         call config_error(error, nml, ig, "parking", "dense_grow_scale", "= "//to_string(dense_grow_scale) &
                           //" must be 0 (no growth) or in (0, 1)")
         return
      end if
      if (.not. (dense_overfill >= 0.0_wp .and. dense_overfill <= 1.0_wp)) then
         call config_error(error, nml, ig, "parking", "dense_overfill", "= "//to_string(dense_overfill) &
                           //" must be in [0, 1]")
         return
      end if
      self%dense_time_limit = dense_time_limit
      self%dense_grow_scale = dense_grow_scale
      self%dense_overfill = dense_overfill
      self%dense_max_failures = dense_max_failures
      self%max_locations = max_locations
      self%max_orientations = max_orientations
      self%max_sizes = max_sizes
      self%max_shapes = max_shapes
      self%max_failures = max_failures
      self%n_ext = n_ext
      self%n_box = n_box
      self%certified = certified
      if (.not. (contact_gap >= 1.0e-4_wp .and. contact_gap <= 0.05_wp)) then
         call config_error(error, nml, ig, "parking", "contact_gap", "= "//to_string(contact_gap) &
                           //" must be in [1e-4, 0.05]")
         return
      end if
      self%contact_gap = contact_gap
      select case (to_lower(trim(contact_method)))
      case ("eob")
         self%contact_method = contact_method_enum_eob()
      case ("newton_raphson")
         self%contact_method = contact_method_enum_nr()
      case default
         call config_error(error, nml, ig, "parking", "contact_method", "= '"//trim(contact_method) &
                           //"' must be 'eob' or 'newton_raphson'")
         return
      end select
      select case (to_lower(trim(placement)))
      case ("uniform")
         self%placement = placement_enum_uniform()
      case ("void")
         self%placement = placement_enum_void()
      case default
         call config_error(error, nml, ig, "parking", "placement", "= '"//trim(placement) &
                           //"' must be 'uniform' or 'void'")
         return
      end select
      select case (to_lower(trim(strategy)))
      case ("rsa")
         self%strategy = strategy_enum_rsa()
      case ("dense")
         self%strategy = strategy_enum_dense()
      case default
         call config_error(error, nml, ig, "parking", "strategy", "= '"//trim(strategy) &
                           //"' must be 'rsa' or 'dense'")
         return
      end select
      select case (to_lower(trim(last_particle)))
      case ("closer")
         self%last_particle = last_particle_enum_closer()
      case ("overshoot")
         self%last_particle = last_particle_enum_overshoot()
      case default
         call config_error(error, nml, ig, "parking", "last_particle", "= '"//trim(last_particle) &
                           //"' must be 'closer' or 'overshoot'")
         return
      end select
      select case (to_lower(trim(sieve_carry)))
      case ("rounding")
         self%sieve_carry = sieve_carry_enum_rounding()
      case ("none")
         self%sieve_carry = sieve_carry_enum_none()
      case default
         call config_error(error, nml, ig, "parking", "sieve_carry", "= '"//trim(sieve_carry) &
                           //"' must be 'rounding' or 'none'")
         return
      end select

   contains

      subroutine at_least(var, x, lo)
         character(len=*), intent(in) :: var
         integer, intent(in) :: x, lo
         if (allocated(error)) return
         if (x < lo) call config_error(error, nml, ig, "parking", var, "= "//to_string(x)//" must be >= "//to_string(lo))
      end subroutine at_least

      subroutine reader(lines, stat, msg)
         character(len=*), intent(in) :: lines(:)
         integer, intent(out) :: stat
         character(len=*), intent(inout) :: msg
         read (lines, nml=parking, iostat=stat, iomsg=msg)
      end subroutine reader
   end subroutine load_parking_config

   ! the local namelist variables shadow the enumerators inside load_parking_config
   pure integer function contact_method_enum_eob() result(k)
      k = contact_method%eob
   end function contact_method_enum_eob

   pure integer function contact_method_enum_nr() result(k)
      k = contact_method%newton_raphson
   end function contact_method_enum_nr

   pure integer function placement_enum_uniform() result(k)
      k = placement%uniform
   end function placement_enum_uniform

   pure integer function placement_enum_void() result(k)
      k = placement%void
   end function placement_enum_void

   pure integer function strategy_enum_rsa() result(k)
      k = parking_strategy%rsa
   end function strategy_enum_rsa

   pure integer function strategy_enum_dense() result(k)
      k = parking_strategy%dense
   end function strategy_enum_dense

   pure integer function last_particle_enum_closer() result(k)
      k = last_particle%closer
   end function last_particle_enum_closer

   pure integer function last_particle_enum_overshoot() result(k)
      k = last_particle%overshoot
   end function last_particle_enum_overshoot

   pure integer function sieve_carry_enum_rounding() result(k)
      k = sieve_carry%rounding
   end function sieve_carry_enum_rounding

   pure integer function sieve_carry_enum_none() result(k)
      k = sieve_carry%none
   end function sieve_carry_enum_none

   !> Namelist spelling of a last-particle rule.
   pure function last_particle_name(p) result(s)
      !> One of `last_particle`.
      integer, intent(in) :: p
      character(len=:), allocatable :: s
      if (p == last_particle%overshoot) then
         s = "overshoot"
      else
         s = "closer"
      end if
   end function last_particle_name

   !> Namelist spelling of a carry rule.
   pure function sieve_carry_name(p) result(s)
      !> One of `sieve_carry`.
      integer, intent(in) :: p
      character(len=:), allocatable :: s
      if (p == sieve_carry%none) then
         s = "none"
      else
         s = "rounding"
      end if
   end function sieve_carry_name

   !> Namelist spelling of a strategy.
   pure function strategy_name(p) result(s)
      !> One of `parking_strategy`.
      integer, intent(in) :: p
      character(len=:), allocatable :: s
      if (p == parking_strategy%dense) then
         s = "dense"
      else
         s = "rsa"
      end if
   end function strategy_name

   !> Namelist spelling of a contact method.
   pure function contact_method_name(method) result(s)
      !> One of `contact_method`.
      integer, intent(in) :: method
      character(len=:), allocatable :: s
      if (method == contact_method%newton_raphson) then
         s = "newton_raphson"
      else
         s = "eob"
      end if
   end function contact_method_name

   !> Namelist spelling of a placement.
   pure function placement_name(p) result(s)
      !> One of `placement`.
      integer, intent(in) :: p
      character(len=:), allocatable :: s
      if (p == placement%void) then
         s = "void"
      else
         s = "uniform"
      end if
   end function placement_name

   !> The resolved `&parking` group as namelist text.
   pure function dump_parking_config(self) result(text)
      !> The parking.
      type(parking_config_type), intent(in) :: self
      character(len=:), allocatable :: text
      text = "&parking max_locations = "//to_string(self%max_locations)//", max_orientations = " &
             //to_string(self%max_orientations)//", max_sizes = "//to_string(self%max_sizes)//", max_shapes = " &
             //to_string(self%max_shapes)//", max_failures = "//to_string(self%max_failures) &
             //", contact_method = '"//contact_method_name(self%contact_method)//"', n_ext = " &
             //to_string(self%n_ext)//", n_box = "//to_string(self%n_box)//", certified = " &
             //logical_text(self%certified)//", placement = '"//placement_name(self%placement)//"'"
      ! an 'rsa' run's resolved text stays as before the strategies existed
      if (self%strategy /= parking_strategy%rsa) then
         text = text//", strategy = '"//strategy_name(self%strategy)//"', dense_rounds = "//to_string(self%dense_rounds) &
                //", dense_sweeps = "//to_string(self%dense_sweeps)//", dense_target_acceptance = " &
                //to_string(self%dense_target_acceptance)//", dense_time_limit = "//to_string(self%dense_time_limit) &
                //", dense_grow_scale = "//to_string(self%dense_grow_scale)
         if (self%dense_overfill > 0.0_wp) text = text//", dense_overfill = "//to_string(self%dense_overfill)
         if (self%dense_max_failures > 0) text = text//", dense_max_failures = " &
                                                 //to_string(self%dense_max_failures)
      end if
      if (self%contact_gap /= 1.0e-3_wp) text = text//", contact_gap = "//to_string(self%contact_gap)
      ! likewise the thesis' sieve-volume rules, only when chosen
      if (self%last_particle /= last_particle%closer) text = text//", last_particle = '" &
                                                             //last_particle_name(self%last_particle)//"'"
      if (self%sieve_carry /= sieve_carry%rounding) text = text//", sieve_carry = '" &
                                                           //sieve_carry_name(self%sieve_carry)//"'"
      text = text//" /"//new_line("a")
   end function dump_parking_config
end module anm_config_parking
