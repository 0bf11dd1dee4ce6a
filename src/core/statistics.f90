!> Small statistics helpers shared by the library, the tests and the benchmarks.
!>
!> Usage:
!>     m = median([3.0_wp, 1.0_wp, 2.0_wp])   ! 2
module anm_core_statistics
   use anm_core_kinds, only: wp
   implicit none
   private

   public :: median

contains

   !> Median of a non-empty array: the element of rank (n+1)/2 found by quickselect on a copy
   !> (for even n, the lower of the two middle values averaged with the upper one).
   pure function median(x) result(m)
      !> Values.
      real(wp), intent(in) :: x(:)
      real(wp) :: m
      real(wp), allocatable :: w(:)
      integer :: n
      n = size(x)
      w = x
      call select_rank(w, (n + 1) / 2, m)
      if (mod(n, 2) == 0) m = 0.5_wp * (m + minval(w((n + 1) / 2 + 1:)))
   end function median

   !> The kth smallest element v of w (w is partially reordered: elements after k are >= v).
   pure subroutine select_rank(w, kth, v)
      real(wp), intent(inout) :: w(:)
      integer, intent(in) :: kth
      real(wp), intent(out) :: v
      real(wp) :: pivot, t
      integer :: lo, hi, i, j
      lo = 1
      hi = size(w)
      do while (lo < hi)
         pivot = w((lo + hi) / 2)
         i = lo
         j = hi
         do while (i <= j)
            do while (w(i) < pivot)
               i = i + 1
            end do
            do while (w(j) > pivot)
               j = j - 1
            end do
            if (i <= j) then
               t = w(i)
               w(i) = w(j)
               w(j) = t
               i = i + 1
               j = j - 1
            end if
         end do
         if (kth <= j) then
            hi = j
         else if (kth >= i) then
            lo = i
         else
            exit
         end if
      end do
      v = w(kth)
   end subroutine select_rank
end module anm_core_statistics
