!> Synthetic aggregate-like star shapes with no input files.
!>
!> Each shape is a random real SH expansion with mean radius 1 (a_00 = 2 sqrt(pi)), no degree-1
!> term (centre near the centroid), and statistically isotropic coefficients whose degree power
!> spectrum P(n) = sum_m |a_nm|^2 / a_00^2 follows the real CT particles of NIST's MA111-7-coarse
!> set: P(2) = p2 for the overall elongation and P(n) = c n^(-beta) for the angularity and
!> roughness, n >= 3. Per shape, the degree-2 and the roughness amplitudes are multiplied by
!> independent log-normal factors (the spread between particles seen in the real set). A draw with
!> r <= 0 anywhere (not star-shaped) or r_min < rmin_fraction of the mean radius is rejected and
!> redrawn. The default parameters and the figures they reproduce are in docs/synthetic-shapes.md.
!>
!> Shape k of a set depends only on (seed, k): shapes can be made in parallel and in any order.
!>
!> Usage:
!>     type(synthetic_params_type) :: par
!>     call make_synthetic_shape(par, seed=1_i8, index=5, shape=s, error=err)
module anm_shapes_synthetic
   use anm_core_kinds, only: wp, i8, pi
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string
   use anm_core_random, only: rng_type, new_rng
   use anm_sh_expansion, only: sh_expansion_type, new_sh_expansion_real
   use anm_shapes_star, only: min_radius
   implicit none
   private

   public :: synthetic_params_type, make_synthetic_shape

   !> Parameters of the generator (defaults calibrated on MA111-7-coarse).
   type :: synthetic_params_type
      !> Highest degree of the generated expansion.
      integer :: nmax = 20
      !> Median power of degree 2 (overall elongation), P(2).
      real(wp) :: p2 = 0.056_wp
      !> Roughness amplitude c in P(n) = c n^(-beta), n >= 3.
      real(wp) :: rough_c = 0.244_wp
      !> Roughness exponent beta.
      real(wp) :: rough_beta = 2.85_wp
      !> Log-normal spread (standard deviation of ln amplitude) per shape of P(2).
      real(wp) :: sigma_p2 = 0.5_wp
      !> Log-normal spread per shape of the roughness amplitude.
      real(wp) :: sigma_rough = 0.5_wp
      !> Smallest accepted r_min / mean radius.
      real(wp) :: rmin_fraction = 0.2_wp
      !> Maximum draws per shape before giving up.
      integer :: max_draws = 1000
   end type synthetic_params_type

contains

   !> Make synthetic shape number `index` of the set seeded by `seed` (mean radius 1).
   subroutine make_synthetic_shape(par, seed, index, shape, error, draws)
      !> Generator parameters.
      type(synthetic_params_type), intent(in) :: par
      !> Base seed.
      integer(i8), intent(in) :: seed
      !> Shape number (>= 1); the random stream id.
      integer, intent(in) :: index
      !> Generated expansion.
      type(sh_expansion_type), intent(out) :: shape
      !> Error when no acceptable draw is found or parameters are invalid.
      type(error_type), allocatable, intent(out) :: error
      !> Number of draws used (1 = first draw accepted).
      integer, intent(out), optional :: draws
      type(rng_type) :: rng
      real(wp), allocatable :: a(:, :), b(:, :)
      real(wp) :: a00, amp2, ampr, pn, sig, rmin, th, ph
      integer :: n, m, k, nmax

      nmax = par%nmax
      if (nmax < 0 .or. nmax > 100) then
         call fatal_error(error, "synthetic shapes: nmax = "//to_string(nmax)//" outside 0..100", error_code%value)
         return
      end if
      if (par%p2 < 0.0_wp .or. par%rough_c < 0.0_wp .or. par%sigma_p2 < 0.0_wp .or. par%sigma_rough < 0.0_wp) then
         call fatal_error(error, "synthetic shapes: p2, rough_c, sigma_p2, sigma_rough must be >= 0", error_code%value)
         return
      end if
      call new_rng(rng, seed, int(index, i8))
      allocate (a(0:nmax, 0:nmax), b(0:nmax, 0:nmax))
      a00 = 2.0_wp * sqrt(pi)
      do k = 1, par%max_draws
         a = 0.0_wp
         b = 0.0_wp
         a(0, 0) = a00
         amp2 = exp(par%sigma_p2 * rng%normal())
         ampr = exp(par%sigma_rough * rng%normal())
         do n = 2, nmax
            if (n == 2) then
               pn = par%p2 * amp2
            else
               pn = par%rough_c * real(n, wp)**(-par%rough_beta) * ampr
            end if
            ! isotropic: each of the 2n+1 real orthonormal components has variance P(n) a00^2/(2n+1)
            sig = sqrt(pn / (2 * n + 1)) * a00
            a(n, 0) = sig * rng%normal()
            do m = 1, n
               a(n, m) = sqrt(2.0_wp) * sig * rng%normal()
               b(n, m) = sqrt(2.0_wp) * sig * rng%normal()
            end do
         end do
         call new_sh_expansion_real(shape, a, b)
         call min_radius(shape, rmin, th, ph)
         if (rmin >= par%rmin_fraction) then
            if (present(draws)) draws = k
            return
         end if
      end do
      call fatal_error(error, "synthetic shape "//to_string(index)//": no star-shaped draw in " &
                       //to_string(par%max_draws)//" attempts (lower p2 or rough_c)", error_code%value)
   end subroutine make_synthetic_shape
end module anm_shapes_synthetic
