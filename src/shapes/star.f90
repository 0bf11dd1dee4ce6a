!> Star-shapedness check: an SH surface describes a star-shaped body only where r > 0.
!>
!> The check evaluates r on a Gauss grid with max(4N, 64) polar and twice as many azimuthal
!> nodes (about 8 nodes per half-wavelength of the highest degree), so a negative region
!> narrower than that spacing could be missed; the reported minimum is the smallest sampled r.
!>
!> Usage:
!>     call check_star_shaped(shape, "file.dat", error)
module anm_shapes_star
   use anm_core_kinds, only: wp
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string
   use anm_sh_expansion, only: sh_expansion_type
   use anm_sh_grid, only: sh_grid_type, new_sh_grid, sh_synthesize
   implicit none
   private

   public :: check_star_shaped, min_radius

contains

   !> Smallest r on the check grid and its direction (theta, phi).
   pure subroutine min_radius(shape, rmin, theta, phi)
      !> Particle.
      type(sh_expansion_type), intent(in) :: shape
      !> Smallest sampled radius.
      real(wp), intent(out) :: rmin
      !> Direction where it occurs (radians).
      real(wp), intent(out) :: theta, phi
      type(sh_grid_type) :: grid
      real(wp), allocatable :: r(:, :)
      integer :: nt, loc(2)
      nt = max(64, 4 * shape%nmax)
      grid = new_sh_grid(nt, 2 * nt, shape%nmax)
      allocate (r(nt, 2 * nt))
      call sh_synthesize(grid, shape, r)
      loc = minloc(r)
      rmin = r(loc(1), loc(2))
      theta = grid%sphere%theta(loc(1))
      phi = grid%sphere%phi(loc(2))
   end subroutine min_radius

   !> Error (class not_star) naming `label` when r <= 0 somewhere: the expansion then does not
   !> describe a star-shaped particle.
   subroutine check_star_shaped(shape, label, error)
      !> Particle.
      type(sh_expansion_type), intent(in) :: shape
      !> File name or tag for the message.
      character(len=*), intent(in) :: label
      !> Error when not star-shaped.
      type(error_type), allocatable, intent(out) :: error
      real(wp) :: rmin, th, ph
      call min_radius(shape, rmin, th, ph)
      if (rmin <= 0.0_wp) then
         call fatal_error(error, trim(label)//": not a star-shaped particle: radius r = " &
                          //to_string(rmin)//" <= 0 at theta = "//to_string(th)//", phi = " &
                          //to_string(ph)//" (degree "//to_string(shape%nmax)//")", error_code%not_star)
      end if
   end subroutine check_star_shaped
end module anm_shapes_star
