:- module(dfrl_safety, []).

/** <module> What code from peers may do with the dFRL agent

The dFRL agent's entries in the platform's sandbox (code_safety.pl),
declared through its multifile hooks: the aggregation hooks that a
method sent by a peer (`dfrl inject`) may define, where those hooks were
before they moved to dfrl_aggregation, and the agent's predicates that
sandboxed code may call. Loaded with dfrl_aggregation.pl, so that every
node that runs the agent or its methods knows them.
*/

:- multifile
    code_safety:mobile_hook/1,
    code_safety:moved_hook/2,
    code_safety:agent_api/2.

code_safety:mobile_hook(dfrl_aggregation:aggregate_init/3).
code_safety:mobile_hook(dfrl_aggregation:aggregate_step/4).
code_safety:mobile_hook(dfrl_aggregation:aggregate_final/3).
code_safety:mobile_hook(dfrl_aggregation:method_uses_visits/1).
code_safety:mobile_hook(dfrl_aggregation:method_applies/2).

%   The aggregation hooks were dfrl_agent's before they moved to the
%   module named for them: a method written for the old module is
%   refused with a culprit that names the new one.
code_safety:moved_hook(dfrl_agent:F/A, dfrl_aggregation:F/A) :-
    code_safety:mobile_hook(dfrl_aggregation:F/A).

code_safety:agent_api(dfrl_agent:dfrl_tour_event(A, _, _), self(A)).
code_safety:agent_api(dfrl_agent:dfrl_tour_main(A, _), self(A)).
code_safety:agent_api(dfrl_aggregation:dfrl_method(_), true).
%   The aggregation hooks: their clauses are the node's own or were
%   checked when a peer sent them (mobile_hook/1), so a method may build
%   on another (e.g. call the average's hooks).
code_safety:agent_api(dfrl_aggregation:aggregate_init(_, _, _), true).
code_safety:agent_api(dfrl_aggregation:aggregate_step(_, _, _, _), true).
code_safety:agent_api(dfrl_aggregation:aggregate_final(_, _, _), true).
code_safety:agent_api(dfrl_aggregation:method_uses_visits(_), true).
code_safety:agent_api(dfrl_aggregation:method_applies(_, _), true).
code_safety:agent_api(dfrl_aggregation:aggregate_tables(_, _, _), true).
