!> The `&sieves` group: the gradation, largest sieve first (docs/namelist.md).
!>
!>     &sieves nsieve = 2, min_width = 4.0, 1.0, max_width = 5.0, 2.0, fraction = 0.2, 0.1 /
!>
!> Validates: nsieve in 1..max_sieves and no sieve listed beyond it; per sieve both widths given,
!> finite, 0 < min_width <= max_width < the smallest box edge, listed largest first; fractions
!> finite in [0, 1] summing to at most 1 (fraction_mode 'box'), or shares summing to 1 times a
!> total_fraction in (0, 1] (fraction_mode 'share'); order -1 or 0..100. The fractions are
!> resolved once to target fractions of the box volume.
!>
!> Usage:
!>     call load_sieves_config(sieves, nml, box, error)
module anm_config_sieves
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string, to_lower
   use anm_config_namelist, only: namelist_file_type, find_group, config_error, group_read_error, check_finite, &
      & max_line
   use anm_config_box, only: box_config_type
   use anm_config_format, only: quoted
   implicit none
   private

   public :: sieves_config_type, load_sieves_config, dump_sieves_config, max_sieves

   !> Capacity of the namelist arrays.
   integer, parameter :: max_sieves = 64

   !> The sieves.
   type :: sieves_config_type
      !> Number of sieves.
      integer :: nsieve = 0
      !> Per sieve: width range, mm.
      real(wp), allocatable :: min_width(:), max_width(:)
      !> Per sieve: target fraction of the box volume (resolved from fraction_mode).
      real(wp), allocatable :: target_fraction(:)
      !> Per sieve: order used for the expansion (-1: all coefficients).
      integer, allocatable :: order(:)
      !> Per sieve: shape source: 'synthetic', 'sphere' or a folder/file of NIST coefficient files.
      character(len=512), allocatable :: source(:)
   end type sieves_config_type

contains

   !> Read and validate `&sieves` (required).
   subroutine load_sieves_config(self, nml, box, error)
      !> The sieves.
      type(sieves_config_type), intent(out) :: self
      !> The scanned namelist file.
      type(namelist_file_type), intent(in) :: nml
      !> The box (validated).
      type(box_config_type), intent(in) :: box
      !> Error naming file, line, group and variable.
      type(error_type), allocatable, intent(out) :: error
      real(wp), parameter :: unset = -huge(1.0_wp)
      integer :: nsieve, order(max_sieves)
      real(wp) :: min_width(max_sieves), max_width(max_sieves), fraction(max_sieves), total_fraction
      character(len=16) :: fraction_mode
      character(len=512) :: source(max_sieves)
      namelist /sieves/ nsieve, min_width, max_width, fraction, fraction_mode, total_fraction, source, order
      integer :: ig, stat, i
      character(len=512) :: msg
      character(len=max_line), allocatable :: lines(:)

      nsieve = 0
      min_width = unset
      max_width = unset
      fraction = unset
      fraction_mode = "box"
      total_fraction = unset
      source = "synthetic"
      order = -1
      ig = find_group(nml, "sieves")
      if (ig == 0) then
         call fatal_error(error, nml%path//": namelist group &sieves is missing", error_code%format)
         return
      end if
      lines = nml%groups(ig)%lines
      read (lines, nml=sieves, iostat=stat, iomsg=msg)
      if (stat /= 0) then
         call group_read_error(error, nml, ig, msg, reader)
         return
      end if
      call check_finite(error, nml, ig, "sieves", "min_width", min_width)
      if (allocated(error)) return
      call check_finite(error, nml, ig, "sieves", "max_width", max_width)
      if (allocated(error)) return
      call check_finite(error, nml, ig, "sieves", "fraction", fraction)
      if (allocated(error)) return
      call check_finite(error, nml, ig, "sieves", "total_fraction", [total_fraction])
      if (allocated(error)) return
      if (nsieve < 1 .or. nsieve > max_sieves) then
         call config_error(error, nml, ig, "sieves", "nsieve", "= "//to_string(nsieve)//" must be in 1.." &
                           //to_string(max_sieves))
         return
      end if
      do i = 1, nsieve
         call check_sieve(i)
         if (allocated(error)) return
      end do
      if (any(min_width(nsieve + 1:) /= unset) .or. any(fraction(nsieve + 1:) /= unset)) then
         call config_error(error, nml, ig, "sieves", "nsieve", "= "//to_string(nsieve)//" but more sieves are listed")
         return
      end if
      self%nsieve = nsieve
      self%min_width = min_width(:nsieve)
      self%max_width = max_width(:nsieve)
      self%order = order(:nsieve)
      self%source = source(:nsieve)
      select case (to_lower(trim(fraction_mode)))
      case ("box")
         self%target_fraction = fraction(:nsieve)
         if (total_fraction /= unset) then
            call config_error(error, nml, ig, "sieves", "total_fraction", "is only used with fraction_mode = 'share'")
            return
         end if
      case ("share")
         if (total_fraction == unset .or. total_fraction <= 0.0_wp .or. total_fraction > 1.0_wp) then
            call config_error(error, nml, ig, "sieves", "total_fraction", "must be in (0, 1] with fraction_mode = 'share'")
            return
         end if
         if (abs(sum(fraction(:nsieve)) - 1.0_wp) > 1.0e-6_wp) then
            call config_error(error, nml, ig, "sieves", "fraction", "shares sum to "//to_string(sum(fraction(:nsieve))) &
                              //", not 1")
            return
         end if
         self%target_fraction = fraction(:nsieve) * total_fraction
      case default
         call config_error(error, nml, ig, "sieves", "fraction_mode", "= '"//trim(fraction_mode) &
                           //"' must be 'box' or 'share'")
         return
      end select
      if (sum(self%target_fraction) > 1.0_wp) then
         call config_error(error, nml, ig, "sieves", "fraction", "target fractions sum to " &
                           //to_string(sum(self%target_fraction))//" > 1: impossible")
         return
      end if

   contains

      subroutine check_sieve(i)
         integer, intent(in) :: i
         character(len=:), allocatable :: si
         si = "("//to_string(i)//")"
         if (min_width(i) == unset .or. max_width(i) == unset) then
            call config_error(error, nml, ig, "sieves", "min_width/max_width"//si, "missing")
         else if (min_width(i) <= 0.0_wp) then
            call config_error(error, nml, ig, "sieves", "min_width"//si, "= "//to_string(min_width(i))//" must be > 0 mm")
         else if (max_width(i) < min_width(i)) then
            call config_error(error, nml, ig, "sieves", "max_width"//si, "= "//to_string(max_width(i)) &
                              //" is below min_width = "//to_string(min_width(i)))
         else if (max_width(i) >= minval(box%length)) then
            call config_error(error, nml, ig, "sieves", "max_width"//si, "= "//to_string(max_width(i)) &
                              //" mm: a particle this wide does not fit in the box (smallest edge " &
                              //to_string(minval(box%length))//" mm)")
         else if (fraction(i) == unset) then
            call config_error(error, nml, ig, "sieves", "fraction"//si, "missing")
         else if (fraction(i) < 0.0_wp .or. fraction(i) > 1.0_wp) then
            call config_error(error, nml, ig, "sieves", "fraction"//si, "= "//to_string(fraction(i))//" must be in [0, 1]")
         else if (order(i) < -1 .or. order(i) > 100) then
            call config_error(error, nml, ig, "sieves", "order"//si, "= "//to_string(order(i)) &
                              //" must be -1 (all coefficients) or 0..100")
         else if (len_trim(source(i)) == 0) then
            call config_error(error, nml, ig, "sieves", "source"//si, "is empty")
         end if
         if (allocated(error)) return
         if (i > 1) then
            if (max_width(i) > max_width(i - 1)) then
               call config_error(error, nml, ig, "sieves", "max_width"//si, "sieves must be listed largest first")
            end if
         end if
      end subroutine check_sieve

      subroutine reader(lines, stat, msg)
         character(len=*), intent(in) :: lines(:)
         integer, intent(out) :: stat
         character(len=*), intent(inout) :: msg
         read (lines, nml=sieves, iostat=stat, iomsg=msg)
      end subroutine reader
   end subroutine load_sieves_config

   !> The resolved `&sieves` group as namelist text (fraction_mode 'box', one line per sieve).
   pure function dump_sieves_config(self) result(text)
      !> The sieves.
      type(sieves_config_type), intent(in) :: self
      character(len=:), allocatable :: text
      character(len=*), parameter :: nl = new_line("a")
      integer :: i
      text = "&sieves nsieve = "//to_string(self%nsieve)//", fraction_mode = 'box'"//nl
      do i = 1, self%nsieve
         text = text//"  min_width("//to_string(i)//") = "//to_string(self%min_width(i)) &
                //", max_width("//to_string(i)//") = "//to_string(self%max_width(i)) &
                //", fraction("//to_string(i)//") = "//to_string(self%target_fraction(i)) &
                //", order("//to_string(i)//") = "//to_string(self%order(i)) &
                //", source("//to_string(i)//") = "//quoted(trim(self%source(i)))//nl
      end do
      text = text//"/"//nl
   end function dump_sieves_config
end module anm_config_sieves
